"""Robot problems: models (example-robot-data through pinocchio), task variables,
stacks (TOML) that turn a configuration into a Hierarchy, and scenario definitions."""
