"""Models in and files out: ``scene`` (Scene, Material, Light, ``scene_digest``), ``load`` (``load_scene``
per file format), ``gltf`` (the glTF document reader), ``glb`` (the GLB writer), ``images`` (PNG and
``.npy``, texture decoding), ``messages`` (one-line causes of third-party errors)."""
