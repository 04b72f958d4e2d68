"""``splatgl bench``: frame time against error for renderer configurations, in one run."""
