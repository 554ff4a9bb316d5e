"""The suite's experiment kinds by name. A kind module (``flownav/evaluation/kinds/``) registers itself:

    @register("success", markdown=success_markdown, verdicts=success_verdicts)
    def run(suite, name, spec, out) -> dict: ...

``run`` measures one suite entry through the :class:`~flownav.evaluation.experiments.Suite` it is given and
returns the entry's result; ``markdown(result)`` is its REPORT.md section and ``verdicts(result)`` its lines
of the report's Targets section (from the entry's ``targets`` in the config, copied into the result).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


class Missing(Exception):
    """Something an experiment needs does not exist yet; the message names the command that makes it."""


def _nothing(result: dict) -> list[str]:
    return []


def _own_policies(spec) -> list[str]:
    return list(spec.get("policies") or [])


@dataclass(frozen=True)
class Kind:
    name: str
    run: Callable  # (suite, name, spec, out) -> result dict
    markdown: Callable[[dict], list[str]] = _nothing
    verdicts: Callable[[dict], list[str]] = _nothing
    policies: Callable = _own_policies  # spec -> every policy name the entry uses


KINDS: dict[str, Kind] = {}


def register(name: str, **parts) -> Callable:
    """Register the decorated ``run`` as kind ``name`` (``parts``: markdown, verdicts, policies)."""

    def add(run: Callable) -> Callable:
        if name in KINDS:
            raise ValueError(f"experiment kind {name!r} is registered twice")
        KINDS[name] = Kind(name, run, **parts)
        return run

    return add
