"""Lighting of a solved model: ``edits`` (light and emission edits), ``states`` (named lighting states,
their key times), ``save`` (writing lights back to glTF), ``editor`` (LightEditor), ``relight`` (the
background re-solve) and ``solution_set`` (several lightings on one mesh, blend weights)."""
