"""Model adapters: the model protocol (:mod:`.protocol`) and the doors simulators come in by,
one per ``model.kind`` (:mod:`.registry`)."""
