"""Running nodes: executor, backends, journal and durable files."""
