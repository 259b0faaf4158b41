"""Warnings of a result: through ``warnings.warn`` and ``.warnings``; ``strict=True``
raises instead. Ctrl-C: the partial result rides on the ``KeyboardInterrupt``."""

import contextlib
import warnings as _warnings

from ._errors import SysidWarning, UntrustedResultError


def report(result, strict, what):
    """Warns of ``result.warnings`` (or raises them with ``strict``); returns ``result``."""
    if not result.warnings:
        return result
    if strict:
        raise UntrustedResultError(
            f"{what}: " + "; ".join(result.warnings), result, result.warnings)
    for w in result.warnings:
        _warnings.warn(f"{what}: {w}", SysidWarning, stacklevel=3)
    return result


@contextlib.contextmanager
def partial_as(build):
    """Turns the compiled half's partial result on a ``KeyboardInterrupt`` (or on the
    progress callback's exception) into a result object: ``e.partial``."""
    try:
        yield
    except BaseException as e:
        raw = getattr(e, "partial", None)
        if isinstance(raw, dict):
            e.partial = build(raw)
        raise
