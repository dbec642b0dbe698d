"""The sim-to-real gap diagnosis as typed results: the verdict, where the gap lies, and the
ranked effects with their parameters and held-out shrink (the contract of
``docs/spec/diagnosis.md``, "Machine-readable result"), with the whole ``diagnosis.json`` kept
as :attr:`Diagnosis.results` for what the types leave out.
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Tuple

#: The contract's verdicts: an effect is named, the gap is at the noise floor, or a real gap
#: that no effect of the vocabulary explains.
VERDICTS: Tuple[str, ...] = ("effect", "none", "unattributed")


@dataclass(frozen=True)
class Gap:
    """The held-out gap between the sim and the recording, and the noise it is measured against,
    in roll-moment-coefficient units (Cp for a gap in the pressure channels)."""

    heldout_rms: float
    noise_rms: float
    stream: Optional[str] = None

    @property
    def to_noise(self) -> float:
        """The gap over the noise: below about one, the sim is at the noise floor."""
        return self.heldout_rms / self.noise_rms if self.noise_rms > 0 else math.inf


@dataclass(frozen=True)
class Where:
    """Where the gap lies: the block (``balance``, ``plant``, ``disturbance``, ``coupling``,
    ``sensor``), the angles of attack, the frequency band, and the pressure channels of a
    sensor effect."""

    block: Optional[str]
    alpha_deg: List[float]
    band_hz: Optional[Tuple[float, float]]
    channel: Optional[str]
    channels: List[str]


@dataclass(frozen=True)
class Effect:
    """A named effect: its name in the contract's vocabulary, the block it belongs to, its
    fitted parameters, and the held-out gap before and after it is added (``shrink`` = 1 -
    after / before). ``shrink_measured`` is False where the shrink holds by definition (a dead
    channel has no reading left to compare)."""

    name: str
    block: str
    params: Dict[str, Any]
    heldout_rms_before: float
    heldout_rms_after: float
    shrink: float
    shrink_measured: bool = True
    evidence: Optional[str] = None


@dataclass(frozen=True)
class Diagnosis:
    """What :func:`rollest.diagnose` found: the verdict, where, the ranked effects, and what
    stays unexplained; ``results`` is ``diagnosis.json`` as a dict, ``folder`` and ``page`` the
    report folder and its HTML page when one was written."""

    verdict: str
    gap: Gap
    where: Where
    effects: List[Effect]
    unexplained: Optional[str]
    results: Dict[str, Any] = field(repr=False)
    folder: Optional[Path] = None
    page: Optional[Path] = None

    @staticmethod
    def from_results(
        results: Mapping[str, Any], folder: Optional[Path] = None, page: Optional[Path] = None
    ) -> "Diagnosis":
        """The typed view of a ``diagnosis.json`` (as a dict)."""
        gap = results.get("gap", {})
        where = results.get("where", {})
        band = where.get("band_hz")
        unexplained = results.get("unexplained")
        return Diagnosis(
            verdict=str(results["verdict"]),
            gap=Gap(
                heldout_rms=float(gap.get("heldout_rms", math.nan)),
                noise_rms=float(gap.get("noise_rms", math.nan)),
                stream=gap.get("stream"),
            ),
            where=Where(
                block=where.get("block"),
                alpha_deg=[float(alpha) for alpha in where.get("alpha_deg", [])],
                band_hz=None if band is None else (float(band[0]), float(band[1])),
                channel=where.get("channel"),
                channels=list(where.get("channels", [])),
            ),
            effects=[
                Effect(
                    name=str(effect["name"]),
                    block=str(effect["block"]),
                    params=dict(effect.get("params", {})),
                    heldout_rms_before=float(effect["heldout_rms_before"]),
                    heldout_rms_after=float(effect["heldout_rms_after"]),
                    shrink=float(effect["shrink"]),
                    shrink_measured=bool(effect.get("shrink_measured", True)),
                    evidence=effect.get("evidence"),
                )
                for effect in results.get("effects", [])
            ],
            unexplained=None if unexplained is None else str(unexplained.get("description", unexplained)),
            results=dict(results),
            folder=folder,
            page=page,
        )

    @property
    def first(self) -> Optional[Effect]:
        """The most responsible named effect, if any."""
        return self.effects[0] if self.effects else None

    def summary(self) -> str:
        """One line, as the command line prints it first."""
        if self.verdict == "none":
            return f"none: the held-out gap is at the noise floor ({self.gap.to_noise:.2f} x the noise)"
        if self.verdict == "unattributed":
            return f"unattributed: a real gap ({self.gap.to_noise:.2f} x the noise) that no effect of the vocabulary explains"
        names = ", ".join(f"{effect.name} (shrink {effect.shrink:.2f})" for effect in self.effects)
        return f"effect: {names}"

    def _repr_html_(self) -> str:
        """A notebook shows the verdict, where, and the ranked effects with their parameters."""
        rows = "".join(
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{:.3g}</td><td>{:.3g}</td><td>{:.2f}{}</td></tr>".format(
                html.escape(effect.name),
                html.escape(effect.block),
                html.escape(_params_text(effect.params)),
                effect.heldout_rms_before,
                effect.heldout_rms_after,
                effect.shrink,
                "" if effect.shrink_measured else " (by definition)",
            )
            for effect in self.effects
        )
        table = (
            "<table><thead><tr><th>effect</th><th>block</th><th>parameters</th><th>held-out RMS before</th>"
            f"<th>after</th><th>shrink</th></tr></thead><tbody>{rows}</tbody></table>"
            if self.effects
            else ""
        )
        where = []
        if self.where.block:
            where.append(f"block {html.escape(self.where.block)}")
        if self.where.alpha_deg:
            where.append("alpha " + ", ".join(f"{alpha:g}" for alpha in self.where.alpha_deg) + " deg")
        if self.where.band_hz:
            where.append(f"band {self.where.band_hz[0]:g} to {self.where.band_hz[1]:g} Hz")
        if self.where.channels:
            where.append("channels " + ", ".join(html.escape(channel) for channel in self.where.channels))
        unexplained = f"<p>{html.escape(self.unexplained)}</p>" if self.unexplained else ""
        return (
            f"<div><p><b>Diagnosis: {html.escape(self.verdict)}</b>; held-out gap {self.gap.heldout_rms:.3g} "
            f"({self.gap.to_noise:.2f} x the noise){'; ' if where else ''}{'; '.join(where)}</p>"
            f"{table}{unexplained}</div>"
        )


def _params_text(params: Mapping[str, Any]) -> str:
    """Parameters as ``name = value`` pairs, numbers to four significant digits."""

    def text(value: Any) -> str:
        if isinstance(value, float):
            return f"{value:.4g}"
        if isinstance(value, list):
            return ", ".join(text(item) for item in value)
        return str(value)

    return "; ".join(f"{name} = {text(value)}" for name, value in params.items())
