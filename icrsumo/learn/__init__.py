"""Learned language-conditioned BEV agents: data collection, text encoders, models, training."""
