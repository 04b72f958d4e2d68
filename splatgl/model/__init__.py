"""What a scene is and how it is to be rendered: the scene, its rotations, model transforms, settings and statistics."""
