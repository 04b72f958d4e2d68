"""``splatgl view``: an interactive glfw window over the same renderers as ``splatgl render``.

Modules: :mod:`.app` (the :class:`~.app.Viewer`: what is shown, pacing), :mod:`.window` (the
glfw window and its callbacks), :mod:`.keys` (what each key does), :mod:`.navigation` (the
camera and the input in progress), :mod:`.controls` (pure input -> camera functions),
:mod:`.display` (the frame and the status panel on the window), :mod:`.frames` (which renderer
call makes each view), :mod:`.present` (textures onto the window), :mod:`.overlay` (status
text), :mod:`.screenshot` (F12).
"""
