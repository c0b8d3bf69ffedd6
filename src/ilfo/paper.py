"""The paper's published numbers (Tables 1-4 of Chang et al., RLC 2024), stored as data in
``data/paper/results.json`` with the table, row, column and line of the .tex each cell comes
from, for reports to put beside ilfo's."""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache
from typing import Any

from ilfo.paths import DATA_DIR

PAPER_RESULTS = DATA_DIR / "paper" / "results.json"


@dataclass(frozen=True)
class PaperCell:
    """One number of the paper."""

    table: str
    """``table1`` .. ``table4``."""
    env: str
    algo: str | None
    num_demos: int
    mean: float
    std: float | None
    text: str
    """As printed (e.g. ``0.98 ± 0.02``)."""
    row: str
    column: str
    space: str | None = None
    """Table 3's space: ``s``, ``s,s'`` or ``s,a``."""
    variant: str | None = None
    """Table 4's variant key (``lambda_0.1``, ``w_greedy``, ...)."""

    @property
    def where(self) -> str:
        return f"{self.table}, {self.row} / {self.column}"


@cache
def paper_results() -> dict[str, Any]:
    """The raw data file."""
    return json.loads(PAPER_RESULTS.read_text(encoding="utf-8"))


@cache
def paper_cells() -> tuple[PaperCell, ...]:
    """Every cell of every table."""
    cells = []
    for table in paper_results()["tables"]:
        for c in table["cells"]:
            cells.append(
                PaperCell(
                    table=table["id"],
                    env=c["env"],
                    algo=c["algo"],
                    num_demos=int(c["num_demos"]),
                    mean=float(c["mean"]),
                    std=None if c["std"] is None else float(c["std"]),
                    text=c["text"],
                    row=c["row"],
                    column=c["column"],
                    space=c.get("space"),
                    variant=c.get("variant_key"),
                )
            )
    return tuple(cells)


def paper_score(env: str, algo: str, num_demos: int) -> PaperCell | None:
    """The paper's normalised final score of a task, algo and demo count (Tables 1-2)."""
    for cell in paper_cells():
        if cell.table in ("table1", "table2") and (cell.env, cell.algo, cell.num_demos) == (
            env,
            algo,
            num_demos,
        ):
            return cell
    return None


def paper_ablation(env: str, variant: str) -> PaperCell | None:
    """The paper's percent difference of an OOPS variant from OOPS+TD3 (Table 4, 10 demos)."""
    for cell in paper_cells():
        if cell.table == "table4" and (cell.env, cell.variant) == (env, variant):
            return cell
    return None


def paper_expert_returns() -> dict[str, float]:
    """The paper's expert return of each task (printed under Tables 1 and 2), by env id."""
    returns: dict[str, float] = {}
    for table in paper_results()["tables"]:
        for env, value in (table.get("expert_returns") or {}).items():
            returns.setdefault(env, float(value))
    return returns
