"""NumPy twins of the shader stages, with the same names and array names; the reference rasterizer and the CPU stages compute with them too."""
