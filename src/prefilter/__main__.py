"""``python -m prefilter``: the ``prefilter`` command line."""

from prefilter.cli import main

main()
