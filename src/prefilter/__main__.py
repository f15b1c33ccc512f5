"""``python -m prefilter``: the ``prefilter`` command line."""

from prefilter.cli import main

# guarded: worker processes of a local cluster import this module again (spawn)
if __name__ == "__main__":
    main()
