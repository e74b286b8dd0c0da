"""Lighting of a solved model: ``edits`` (light edits, lighting states, the background relighter,
saving lights back to glTF) and ``solution_set`` (several lightings on one mesh, blend weights)."""
