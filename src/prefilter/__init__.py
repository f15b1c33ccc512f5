"""prefilter: prefiltered shading for area lights, normal maps, colour maps and glints.

One package per method (``ltc``, ``multiscale``, ``leadr``, ``colormap``, ``glints``) over shared
foundations (``microfacet``, ``sphere``, ``texture``, ``render``).
"""

from prefilter.errors import PrefilterError

__version__ = "0.1.0"
__all__ = ["PrefilterError", "__version__"]
