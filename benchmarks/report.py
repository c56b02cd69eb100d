"""The suite's report: Markdown sections, PNG charts and the raw rows, in one folder.

`Report` collects sections while the suite runs and writes `README.md` (with the command,
date and machine) and `data.json` when the session ends. Charts go to a `.partial` folder
that replaces the report only then, so an interrupted run leaves the last report whole.
"""

from __future__ import annotations

import datetime
import json
import platform
import shutil
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numba

from common import cpu

HERE = Path(__file__).parent
FULL = HERE / "report"  # committed: made by a full run
QUICK = HERE / "report-quick"  # the quick mode's (CI), not committed


def machine() -> str:
    """CPU, cores, Numba threads and JAX's backend, in one line."""
    import jax

    return (
        f"{cpu()}, Numba threads {numba.get_num_threads()}, "
        f"JAX {jax.__version__} on {jax.default_backend()}, Python {platform.python_version()}"
    )


@dataclass
class Report:
    """Sections of Markdown and data rows, written to `folder` by `write`."""

    folder: Path
    quick: bool
    sections: dict[str, list[str]] = field(default_factory=dict)
    data: dict[str, object] = field(default_factory=dict)

    @property
    def partial(self) -> Path:
        """The folder being written until `write` moves it into place."""
        return self.folder.with_name(self.folder.name + ".partial")

    def start(self) -> None:
        """A fresh, empty partial folder (a stale chart must not survive a rerun)."""
        shutil.rmtree(self.partial, ignore_errors=True)
        self.partial.mkdir(parents=True)

    def chart(self, name: str) -> Path:
        """Path of a chart in the report."""
        return self.partial / name

    def add(self, title: str, lines: list[str], data: object = None) -> None:
        """A section (replacing one of the same title) and its rows for data.json."""
        self.sections[title] = lines
        if data is not None:
            self.data[title] = data

    def write(self, order: list[str]) -> None:
        """README.md with the sections in `order` (then any others) and data.json."""
        command = (
            "pytest " + " ".join(sys.argv[1:]) if "pytest" in sys.argv[0] else " ".join(sys.argv)
        )
        lines = [
            "# dpm benchmark report" + (" (quick mode)" if self.quick else ""),
            "",
            f"Made by `{command}` on {datetime.date.today().isoformat()}.",
            "",
            f"Machine: {machine()}.",
            "",
        ]
        titles = [t for t in order if t in self.sections]
        titles += [t for t in self.sections if t not in titles]
        for title in titles:
            lines += [f"## {title}", "", *self.sections[title], ""]
        (self.partial / "README.md").write_text("\n".join(lines))
        (self.partial / "data.json").write_text(json.dumps(self.data, indent=1, default=float))
        shutil.rmtree(self.folder, ignore_errors=True)
        self.partial.rename(self.folder)
