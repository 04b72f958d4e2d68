"""What a render returns, as data: the layers a renderer returns (:mod:`.layers`), the geometry
it composites into and the compositing rule (:mod:`.under`); and how every file is written
whole (:mod:`.atomic`, several files all or nothing in :mod:`.files`).  No image or video
library is imported here: image and video files are :mod:`splatgl.imagefiles`."""
