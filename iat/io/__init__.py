"""Models in and files out: ``scene`` (Scene, Material, Light, ``load_scene``), ``glb`` (the GLB writer),
``images`` (PNG and ``.npy``)."""
