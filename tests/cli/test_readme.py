"""The README's two set-up commands are what CI runs, verbatim."""

import re
from pathlib import Path

ROOT = Path(__file__).parents[2]


def test_readme_setup_commands_are_ci_commands():
    readme = (ROOT / "README.md").read_text()
    section = readme.split("## Set-up", 1)[1].split("\n## ", 1)[0]
    commands = re.findall(r"```bash\n(.+?)\n```", section)
    assert len(commands) == 2
    ci = [l for l in (ROOT / ".ci" / "run").read_text().splitlines()
          if l.startswith("python3 -m venv")]
    assert ci == commands
