"""Agents: the protocol, built-in privileged agents and the registry."""
