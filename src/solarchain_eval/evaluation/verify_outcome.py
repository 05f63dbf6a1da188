"""What :func:`~.verify.verify_run` finds: one :class:`PolicyVerification` per policy of a run
(``verified``, ``differs`` or ``cannot rebuild``) inside a :class:`RunVerification`, with the
lines the ``verify`` command prints.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..common.redaction import redact_text
from .verify_checks import Difference

VERIFIED, DIFFERS, CANNOT_REBUILD = "verified", "differs", "cannot rebuild"


@dataclass(frozen=True)
class PolicyVerification:
    """The outcome for one policy: ``status`` is ``verified``, ``differs`` or ``cannot rebuild``.

    ``episodes`` counts the episodes compared, ``replayed`` the earlier episodes re-run only to
    bring a stateful agent to the state it had (not compared).
    """

    policy: str
    status: str
    episodes: int = 0
    replayed: int = 0
    difference: Difference | None = None
    reason: str = ""

    def line(self) -> str:
        if self.status == VERIFIED:
            replayed = f"; {self.replayed} earlier episode(s) replayed in order" if self.replayed else ""
            return f"{self.policy}: verified ({self.episodes} episode{'' if self.episodes == 1 else 's'}{replayed})"
        if self.status == DIFFERS:
            d = self.difference
            if d is None:
                return f"{self.policy}: differs: {self.reason}"
            return (
                f"{self.policy}: differs: episode {d.episode} of run seed {d.run_seed}, metric {d.metric}: "
                f"recorded {d.recorded}, re-run {d.rerun}"
            )
        return f"{self.policy}: cannot rebuild ({self.reason})"


@dataclass(frozen=True)
class RunVerification:
    """Everything :func:`verify_run` found about one run directory."""

    run_dir: Path
    checksum_problems: tuple[str, ...]
    protocol_id: str
    protocol_problems: tuple[str, ...]
    policies: tuple[PolicyVerification, ...]
    files_checked: int = 0
    rollout_problems: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        """Checksums, protocol and rollouts agree and no rebuilt policy differs."""
        problems = self.checksum_problems or self.protocol_problems or self.rollout_problems
        return not problems and all(p.status != DIFFERS for p in self.policies)

    def lines(self) -> list[str]:
        """One line per policy, one per problem, then the checksum result and protocol id (redacted:
        a recorded spec may carry credentials)."""
        out = [p.line() for p in self.policies]
        out += [f"rollouts: {problem}" for problem in self.rollout_problems]
        out += [f"checksum: {problem}" for problem in self.checksum_problems]
        out += [f"protocol: {problem}" for problem in self.protocol_problems]
        checksums = (
            f"checksums match ({self.files_checked} files)"
            if not self.checksum_problems
            else f"checksums FAIL ({len(self.checksum_problems)} problem(s))"
        )
        protocol = "" if not self.protocol_problems else " (inconsistent with the metadata)"
        out.append(f"{checksums}; protocol {self.protocol_id or '(none recorded)'}{protocol}")
        return [redact_text(line) for line in out]
