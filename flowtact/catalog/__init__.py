"""Entry-point registries: blocks by name and the presets domains publish."""
