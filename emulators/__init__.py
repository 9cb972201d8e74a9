"""emulators layer."""

if __name__ != "exohil.emulators":  # e.g. `import emulators` from the repository root
    raise ImportError(f"import exohil.emulators, not {__name__}: the folder is a subpackage of "
                      "exohil, and a second copy of its modules would not share their classes")

