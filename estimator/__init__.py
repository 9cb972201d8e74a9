"""estimator layer."""

if __name__ != "exohil.estimator":  # e.g. `import estimator` from the repository root
    raise ImportError(f"import exohil.estimator, not {__name__}: the folder is a subpackage of "
                      "exohil, and a second copy of its modules would not share their classes")

