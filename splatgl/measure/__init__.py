"""The measuring packages, apart from the renderer's core: benchmarks (``bench``), stress cases
(``stress``), the conformance kit (``conformance``) and image evaluation (``evaluation``)."""
