"""harness layer."""

if __name__ != "exohil.harness":  # e.g. `import harness` from the repository root
    raise ImportError(f"import exohil.harness, not {__name__}: the folder is a subpackage of "
                      "exohil, and a second copy of its modules would not share their classes")

