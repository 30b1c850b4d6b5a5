"""`.ci/run` runs exactly the README's test command, so what CI checks is what users run."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _bash_blocks(text: str) -> list[str]:
    return [b.strip() for b in re.findall(r"```bash\n(.*?)```", text, flags=re.S)]


def test_ci_runs_the_readme_test_command():
    readme = (ROOT / "README.md").read_text()
    section = readme.split("## Run the tests", 1)[1]
    command = _bash_blocks(section)[0]
    assert "pytest" in command
    ci_lines = [
        ln.strip()
        for ln in (ROOT / ".ci" / "run").read_text().splitlines()
        if ln.strip() and not ln.lstrip().startswith("#")
    ]
    assert command in ci_lines, f"{command!r} not in .ci/run"


def test_ci_script_fails_on_errors():
    text = (ROOT / ".ci" / "run").read_text()
    assert "set -euo pipefail" in text
