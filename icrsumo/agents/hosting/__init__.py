"""Agents hosted apart from the loop that calls them: watching calls against hangs
(:mod:`~icrsumo.agents.hosting.watch`), batched inference across workers
(:mod:`~icrsumo.agents.hosting.batching`, :mod:`~icrsumo.agents.hosting.batched`), serving an agent
over HTTP (:mod:`~icrsumo.agents.hosting.serve`) and a local language-model server
(:mod:`~icrsumo.agents.hosting.llmserver`). Above :mod:`icrsumo.guards` (a watched guard call times
out as the guard's); nothing in :mod:`icrsumo.agents` proper imports it."""
