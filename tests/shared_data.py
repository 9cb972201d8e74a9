"""Where the tests find the data shared beside the repository (``../shared``: the real
recordings, the other lab's sample, the NAO robot files): ``$EXOHIL_SHARED`` if set, else
the folder beside this checkout. Not ``exohil.harness.paths.SHARED_DIR``, which an installed
package (tox installs one) resolves beside site-packages. Tests that need a file there skip
when it is absent, with a reason ``make test`` lists (``-rs``)."""

import os
from pathlib import Path

SHARED_DIR = Path(os.environ.get("EXOHIL_SHARED")
                  or Path(__file__).resolve().parents[2] / "shared")
