"""The order stage: which splats a view can see (cull) and in which order they blend (sort), with optional compiled kernels."""
