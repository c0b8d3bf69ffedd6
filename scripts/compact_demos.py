"""Rewrite the shipped experts' demo files with float32 observations and actions where that loses
nothing (``ilfo.demos.npz.float32_is_lossless``), refresh each card's sha256 of demos.npz, and
print what float32 changes in OOPS's and PWIL's rewards (demo 1 rewarded against demo 0, the
learner's episode kept float64 as an environment gives it).

    python scripts/compact_demos.py            # measure only
    python scripts/compact_demos.py --write    # and replace the files
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
from pathlib import Path

import numpy as np

from ilfo import demos
from ilfo.rewards.oops import OOPS
from ilfo.rewards.pwil import PWIL


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="replace the files")
    parser.add_argument("--experts", type=Path, default=Path("data/experts"))
    args = parser.parse_args()
    for path in sorted(args.experts.glob("*/demos.npz")):
        old = demos.load(path)
        tmp = path.with_suffix(".new.npz")
        demos.save(tmp, old.episodes, old.env_id, old.provenance)
        new = demos.load(tmp)
        learner = old.episodes[1].observations
        changes = []
        for reward_cls in (OOPS, PWIL):
            r64 = np.asarray(reward_cls([old.episodes[0].observations])(learner).rewards)
            r32 = np.asarray(reward_cls([new.episodes[0].observations])(learner).rewards)
            changes.append(np.abs(r64 - r32).max() / np.abs(r64).mean())
        print(
            f"{old.env_id}: observations {old.episodes[0].observations.dtype} -> "
            f"{new.episodes[0].observations.dtype}, {path.stat().st_size / 1e6:.2f} -> "
            f"{tmp.stat().st_size / 1e6:.2f} MB; max |reward change| / mean |reward|: "
            f"OOPS {changes[0]:.1e}, PWIL {changes[1]:.1e}"
        )
        if not args.write:
            tmp.unlink()
            continue
        os.replace(tmp, path)
        card_path = path.parent / "card.json"
        if card_path.is_file():
            card = json.loads(card_path.read_text())
            card.setdefault("sha256", {})["demos.npz"] = hashlib.sha256(
                path.read_bytes()
            ).hexdigest()
            card_path.write_text(json.dumps(card, indent=2) + "\n")


if __name__ == "__main__":
    main()
