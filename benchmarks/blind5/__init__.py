"""A fifth generator of recordings with hidden effects, written blind (README.md)."""
