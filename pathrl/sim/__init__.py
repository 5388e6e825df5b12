"""Physics scenes (PyBullet) for the sensory-feedback tasks."""
