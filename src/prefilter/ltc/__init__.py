"""Linearly transformed cosines: the distribution, polygon integration and GGX tables."""

from prefilter.ltc.ltc import LTC

__all__ = ["LTC"]
