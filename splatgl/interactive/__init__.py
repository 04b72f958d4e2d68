"""Interactive viewing: a frame-time budget while the camera moves (:mod:`.budget`), the levels it
draws at (:mod:`.draft`), the level-of-detail tree it draws from (:mod:`.lod_cache`), and the
session that refines to the exact frame when the camera rests (:mod:`.session`)."""
