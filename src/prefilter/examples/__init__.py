"""Example scenes shipped with the package, reachable as ``example:NAME`` wherever a scene path is
read (``prefilter render example:showcase --out showcase.exr``).

Each example is a plain scene file (``docs/scenes.md``) next to this module: ``prefilter examples``
lists them, ``prefilter examples NAME`` prints one to copy and edit. The files are the scenes of
``prefilter demo`` and of the scene documentation, written by ``tools/gen_examples.py``.
"""

from __future__ import annotations

import os
from pathlib import Path

from prefilter.errors import PrefilterError

__all__ = ["EXAMPLES", "PREFIX", "names", "path", "resolve"]

#: A scene argument starting with this names a shipped example.
PREFIX = "example:"

#: name -> one line: what the scene shows and the methods to render it with.
EXAMPLES = {
    "showcase": "the demo's showcase: Gaussian-bump GGX plane under a quad light, ~1 texel per "
                "pixel (ltc, ltc-multiscale, reference)",
    "showcase-far": "the showcase from 16x farther, ~16 texels per pixel, where prefiltering "
                    "matters (ltc vs ltc-multiscale, reference)",
    "brushed-metal": "anisotropic GGX: brushed plane and sphere under a quad light (ltc-aniso vs "
                     "ltc, reference)",
    "multiscale-brushed": "the showcase plane with the built-in brushed normal map, ~16 texels "
                          "per pixel (ltc-multiscale vs ltc, reference)",
    "multiscale-flakes": "the showcase plane with the built-in flakes normal map, ~16 texels per "
                         "pixel (ltc-multiscale vs ltc, reference)",
    "leadr": "height-mapped sphere on a height-mapped plane under a point light (leadr-point vs "
             "ltc, reference)",
    "colormap": "colour-mapped noise texture on a plane and a sphere, colour term only "
                "(colormap-filtered vs colormap-naive)",
    "glints": "metallic plane with a 128^2 flakes normal map under a point light (glints vs "
              "glints-direct; the first render bakes its pyramid, ~1-2 min)",
    "plane-and-sphere": "the example of docs/scenes.md: bumpy copper plane and a flaked sphere, "
                        "quad and directional light (ltc, ltc-multiscale, reference)",
    "kettle": "brushed-metal body of revolution on a glossy floor that reflects it, two small "
              "quad lights and a sky (path, glints / glints-direct with bounces=2)",
    "flake-panel": "curved flake-coated panel (a car's bonnet) under a sky and a point light "
                   "(path, glints)",
    "brushed-room": "box of brushed-metal walls under three ceiling quad lights (path with "
                    "bounces=4, glints with bounces=2)",
}

_DIR = Path(__file__).resolve().parent


def names() -> list[str]:
    """The example names, in listing order."""
    return list(EXAMPLES)


def path(name: str) -> Path:
    """The scene file of example ``name``; :class:`PrefilterError` listing the names if unknown."""
    if name not in EXAMPLES:
        raise PrefilterError(f"scene: expected {PREFIX}NAME with NAME one of "
                             f"{', '.join(EXAMPLES)}, got {PREFIX}{name}")
    return _DIR / f"{name}.json"


def resolve(scene):
    """``scene`` with ``example:NAME`` replaced by the example's file path; anything else as is."""
    if isinstance(scene, (str, os.PathLike)):
        s = os.fspath(scene)
        if isinstance(s, str) and s.startswith(PREFIX):
            return path(s[len(PREFIX):])
    return scene
