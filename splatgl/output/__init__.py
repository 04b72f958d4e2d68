"""What a render returns, as data: the layers a renderer returns (:mod:`.layers`), the geometry
it composites into and the compositing rule (:mod:`.under`).  No file is read or written here:
image and video files are :mod:`splatgl.imagefiles`, the atomic writer :mod:`splatgl.writing`."""
