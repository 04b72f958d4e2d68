"""Image and video files: reading and writing PNG, TIFF and EXR through OpenImageIO and H.264
video through PyAV; the image format table, frame sequences and their records, a render's layers
as files, pictures for people (heat maps, colourised depth) and ``--under`` geometry files.

The render path (cameras, output, twins, order, GL, reference, renderers) never imports this
package nor an image or video library (the contracts in pyproject.toml): importing a renderer
loads none of them.  What a render returns and how it is composited is data, in
:mod:`splatgl.output`.
"""
