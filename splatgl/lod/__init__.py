"""Level of detail: a hierarchy built offline by merging neighbours (:mod:`.build`), stored in a
PLY beside the leaves (:mod:`.io`), and a per-view cut through it (:mod:`.cut`) rendered by the
quad path (:mod:`.render`)."""
