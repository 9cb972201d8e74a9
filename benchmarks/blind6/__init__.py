"""blind6: an independent generator of textile-garment recordings with hidden effects."""
