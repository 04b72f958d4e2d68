"""Camera models, the per-frame view, and camera files."""
