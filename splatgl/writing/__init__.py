"""How every file splatgl writes is written: whole or not at all, through a hidden temporary
renamed onto the target (:mod:`.atomic`), several files of one command all or nothing, and
never onto one of the command's inputs nor over an existing file without ``--force``
(:mod:`.outputs`).  No image or video library is imported here (image files are
:mod:`splatgl.imagefiles`); scene formats, camera and path files, edits and reports use it."""
