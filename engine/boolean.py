"""Booleans between adaptive fields (Ren et al., Sec. 5)."""


def union(a, b, *, blend=0.0):
    raise NotImplementedError


def intersection(a, b, *, blend=0.0):
    raise NotImplementedError


def difference(a, b, *, blend=0.0):
    raise NotImplementedError
