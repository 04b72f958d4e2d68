"""The per-splat math of splatgl, in NumPy: projection, covariances, extents, SH colour, surfels,
normals, blending, mesh ray casting.  Every renderer computes with it or is checked against it:
the reference rasterizer and the CPU stages call it; each shader stage and each numba kernel
names the function here that is its twin (same names, same array names) and a test compares
them (tests/splatmath/test_twins.py, tests/renderers/test_cpu_kernels.py)."""
