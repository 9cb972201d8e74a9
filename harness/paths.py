"""Where the repository's bundled data lives (the editable install runs from the checkout)."""

from __future__ import annotations

from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
FIXTURES_DIR = REPO_ROOT / "fixtures"
MODELS_DIR = FIXTURES_DIR / "models"
SHARED_DIR = REPO_ROOT.parent / "shared"
