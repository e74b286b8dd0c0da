"""The IAT desktop viewer and tuning tool (``iat view``, ``python -m viewer``).

:mod:`viewer.app` runs the window; :mod:`viewer.state` holds what it shows, :mod:`viewer.panels`
the widgets that change it, :mod:`viewer.controls` the input, :mod:`viewer.jobs` and
:mod:`viewer.bake_worker` the background work, :mod:`viewer.navigation` and :mod:`viewer.picking`
the pure camera and picking logic, :mod:`viewer.bench` the measurements that drive the app.
"""
