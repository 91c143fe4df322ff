"""A learned configuration's fitted parameters as a run carries them (light to import: the
study's config holds them)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from opfbench.learned.rules import LearnedParams

LEARNED_DIR = "learned"  # the run folder's fitted rules: learned/<case>--<label>.json
TRAIN_DIR = "train"  # the run folder's training runs (train/reference, train/learned) and train/summary.csv


@dataclass(frozen=True)
class Fitted:
    """A learned configuration's parameters for one case of a run: `ref` names them (the
    run folder's `learned/<file>.json`, or the file `params=` gives), `sha256` is their
    text's hash, `text` the text (shipped to the workers, installed there under `ref`)."""

    case: str
    label: str
    ref: str
    sha256: str
    text: str

    @classmethod
    def of(cls, case: str, label: str, ref: str, params: LearnedParams) -> "Fitted":
        return cls(case, label, ref, params.digest, params.text())

    def as_dict(self) -> dict:
        """The run configuration's record (no text: the file is in the folder or given)."""
        return {"case": self.case, "label": self.label, "ref": self.ref, "sha256": self.sha256}

    def parsed(self) -> LearnedParams:
        from opfbench.learned.rules import LearnedParams

        return LearnedParams.parse(self.text, self.ref)
