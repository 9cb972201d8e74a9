"""estimator layer."""
