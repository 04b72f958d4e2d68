"""OpenGL plumbing: the one context factory, shader loading, and GPU buffers."""
