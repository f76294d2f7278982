"""scenes: builders, built-in scenes and the scene file (TOML) for acoustisim."""
