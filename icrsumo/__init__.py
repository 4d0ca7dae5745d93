"""icrsumo: instruction-robustness evaluation of language-conditioned driving agents on SUMO."""

__version__ = "0.1.0"
