"""The render paths: the quad path, the tile renderer and stereo pairs."""
