"""Colour-map filtering (Heitz, Nowrouzezahrai, Poulin, Neyret 2013, "Filtering Color Mapped
Textures and Surfaces").
"""

from prefilter.colormap.table import (
    EDGES,
    ColormapTable,
    as_colormap,
    gaussian_operator,
    lookup,
    prefilter_table,
)

__all__ = ["EDGES", "ColormapTable", "as_colormap", "gaussian_operator", "lookup",
           "prefilter_table"]
