"""Deprecated: the bundled-suite pipeline moved to :mod:`icrsumo.bundled`; these names stay
importable from here."""

from __future__ import annotations

from .bundled import DEFAULT_ROUTE, DEFAULT_SUITE, bundled_route, cache_root

__all__ = ["DEFAULT_ROUTE", "DEFAULT_SUITE", "bundled_route", "cache_root"]
