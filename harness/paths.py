"""Where exohil's bundled data lives, found through the installed package.

The fixtures (recordings and reference models) ship inside the ``exohil`` package as
``exohil/fixtures`` (a symlink to the repository's ``fixtures/`` in a checkout, real files in a
wheel), so ``exohil demo`` finds them from any folder after ``pip install``. Two environment
variables override the defaults:

* ``EXOHIL_FIXTURES``: another fixtures folder (same layout: ``*.mcap`` and ``models/*.npz``);
* ``EXOHIL_SHARED``: the folder of shared real data (``realdata/``, ``robots/``, ``samples/``),
  by default ``../shared`` beside a checkout.
"""

from __future__ import annotations

import os
from pathlib import Path

import exohil

PACKAGE_DIR = Path(exohil.__file__).parent
FIXTURES_DIR = Path(os.environ.get("EXOHIL_FIXTURES") or PACKAGE_DIR / "fixtures")
MODELS_DIR = FIXTURES_DIR / "models"
SHARED_DIR = Path(os.environ.get("EXOHIL_SHARED") or PACKAGE_DIR.resolve().parents[1] / "shared")
SHOULDER_IK_DIR = SHARED_DIR / "realdata" / "shoulder-ik"
