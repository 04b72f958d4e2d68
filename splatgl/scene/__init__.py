"""What a scene is and how it is to be rendered: the scene, its rotations, scene transforms, settings and statistics."""
