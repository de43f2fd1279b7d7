"""Model adapters: the model protocol and the doors through which simulators come in."""
