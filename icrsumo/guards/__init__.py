"""Instruction guards: defences between the instruction stream and any agent.

For each new instruction a guard decides *pass* (the agent is shown it) or *block* (the agent
keeps the last passed one; "Follow the road." while none has passed). Guarded agents are their
own result rows (``bev-ngram-aug+guard:plan``). :mod:`.base` holds the protocol and what a guard
sees, :mod:`.registry` the names (``text``, ``plan``, ``llm`` and plugins), one module per guard.
"""
