"""``splatgl view``: an interactive glfw window over the same renderers as ``splatgl render``.

Modules: :mod:`.controls` (pure input -> camera functions), :mod:`.app` (window, input, pacing),
:mod:`.frames` (which renderer call makes each view), :mod:`.present` (textures onto the
window), :mod:`.overlay` (status text), :mod:`.screenshot` (F12).
"""
