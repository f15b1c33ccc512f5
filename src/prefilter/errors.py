"""The package's one exception type for bad input.

Every check at a public boundary raises :class:`PrefilterError` (a ``ValueError``) with a message
that names the parameter (or file field), the value received and what was expected. The CLI turns
it into a one-line error and exit code 2.
"""

from __future__ import annotations


class PrefilterError(ValueError):
    """Invalid input to a prefilter function, file or command."""


class TableFileError(PrefilterError):
    """A table or baked-map file that is missing, truncated, of the wrong version or layout."""
