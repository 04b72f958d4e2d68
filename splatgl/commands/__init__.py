"""Sub-commands of the ``splatgl`` CLI, one module each (discovered by :mod:`splatgl.cli`)."""
