"""The ``browser`` fixture: one headless Chromium per test module.

It FAILS when Debian's chromium / chromedriver are missing, unless PREFILTER_SKIP_BROWSER=1 (then
the browser tests are skipped with the reason).
"""

import os

import pytest

from prefilter.viewer.browser import CHROMEDRIVER, CHROMIUM


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    missing = [p for p in (CHROMIUM, CHROMEDRIVER) if not os.access(p, os.X_OK)]
    if missing:
        if os.environ.get("PREFILTER_SKIP_BROWSER") == "1":
            pytest.skip(f"PREFILTER_SKIP_BROWSER=1 and {', '.join(missing)} missing")
        pytest.fail(f"{', '.join(missing)} missing: install Debian's chromium and chromium-driver "
                    "(or set PREFILTER_SKIP_BROWSER=1 to skip the browser tests)")
    from prefilter.viewer.browser import chromium

    driver = chromium(tmp_path_factory.mktemp("chromium-profile"))
    yield driver
    driver.quit()
