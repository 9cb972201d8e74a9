"""formats layer."""

if __name__ != "exohil.formats":  # e.g. `import formats` from the repository root
    raise ImportError(f"import exohil.formats, not {__name__}: the folder is a subpackage of "
                      "exohil, and a second copy of its modules would not share their classes")

