"""conformance layer."""

if __name__ != "exohil.conformance":  # e.g. `import conformance` from the repository root
    raise ImportError(f"import exohil.conformance, not {__name__}: the folder is a subpackage of "
                      "exohil, and a second copy of its modules would not share their classes")

