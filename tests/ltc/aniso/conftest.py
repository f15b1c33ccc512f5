import pytest


@pytest.fixture(scope="session")
def table():
    from prefilter.ltc import AnisoGGXTable

    return AnisoGGXTable.load()
