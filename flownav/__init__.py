"""flownav: navigation in 3D unsteady flows with geo teachers and ego students."""
