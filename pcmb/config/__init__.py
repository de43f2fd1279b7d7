"""Study configuration: YAML loader, schema, messages and checks."""
