"""The bottom layer: what every other layer uses and that knows nothing of driving. Errors that
name a field (:mod:`~icrsumo.core.errors`), the shared records and vocabularies
(:mod:`~icrsumo.core.types`, :mod:`~icrsumo.core.vocab`), files written whole
(:mod:`~icrsumo.core.fsio`), process pools (:mod:`~icrsumo.core.procs`), packaged data
(:mod:`~icrsumo.core.resources`), defaults, device names, document checking and the HTTP side of
the OpenAI-compatible protocol (:mod:`~icrsumo.core.llmio`). Imports nothing of icrsumo above it."""
