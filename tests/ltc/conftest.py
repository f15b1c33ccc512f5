"""Make the shared NumPy twins (``ltc_numpy`` here, ``gbuffer_numpy`` in ``tests/render``)
importable under ``--import-mode=importlib``."""

import os
import sys

_here = os.path.dirname(os.path.abspath(__file__))
for _dir in (_here, os.path.join(os.path.dirname(_here), "render")):
    if _dir not in sys.path:
        sys.path.insert(0, _dir)
