"""scenes: builders, built-in scenes and the scene file (TOML) for acoustisim.

Modules
-------
builders
    Scene objects (post, edge prism, cylinder, sphere, plate, user mesh) and the default sonar.
builtin
    Named scenes: ``thesis-tank`` and the free-field validation scenes ``free-*``.
scene_file
    Load, validate and save scene files; ``load_scene`` also takes a built-in name.
validation
    Physical checks: objects in the water and apart, the sonar's transducers clear.
summary
    The JSON-ready description printed by ``acoustisim scene show``.
tessellation
    The sagitta criterion that sets how finely curved objects are meshed.
"""
