"""Instruction guards: defences between the instruction stream and any agent.

For each new instruction a guard decides *pass* (the agent is shown it), *block* (under the
``keep`` block policy the agent keeps what it was shown before, "Follow the road." while nothing
has passed; under ``navigator`` it is shown the navigation plan's instruction in the route's
baseline words) or *repair* (the agent is shown the guard's repaired text). Guarded agents are
their own result rows (``bev-ngram-aug+guard:plan``, ``bev-ngram-aug+guard:plan+navigator``).
:mod:`.base` holds the protocol and what a guard
sees, :mod:`.registry` the names (``text``, ``plan``, ``llm`` and plugins), one module per guard.
"""
