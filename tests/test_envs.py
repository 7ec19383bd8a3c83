"""The rules' conda environments agree with environment.txt, and `snakemake --lint` is clean."""
import re
import subprocess
import sys

import yaml

from conftest import ROOT


def pins(lines) -> dict:
    out = {}
    for line in lines:
        match = re.fullmatch(r"\s*([A-Za-z0-9_.\-]+)==([^\s#]+)\s*", line)
        if match:
            out[match.group(1).lower()] = match.group(2)
    return out


def test_every_rule_environment_pins_what_environment_txt_pins():
    environment = pins((ROOT / "environment.txt").read_text().splitlines())
    envs = sorted((ROOT / "workflow" / "envs").glob("*.yaml"))
    assert envs
    for path in envs:
        spec = yaml.safe_load(path.read_text())
        assert "python=3.11" in spec["dependencies"], path.name
        pip = next(d["pip"] for d in spec["dependencies"] if isinstance(d, dict))
        packages = [p for p in pip if not p.startswith("-e")]
        assert all("==" in p for p in packages), f"{path.name}: unpinned {packages}"
        for name, version in pins(packages).items():
            assert environment.get(name) == version, f"{path.name}: {name}=={version}, environment.txt {environment.get(name)}"
        assert "-e ../.." in pip, f"{path.name} must install the project"


def test_every_rule_has_an_environment_and_the_linter_is_content():
    rules = "\n".join(p.read_text() for p in (ROOT / "workflow" / "rules").glob("*.smk"))
    used = set(re.findall(r'conda:\n\s+"\.\./envs/([a-z_]+)\.yaml"', rules))
    assert used == {p.stem for p in (ROOT / "workflow" / "envs").glob("*.yaml")}
    result = subprocess.run([sys.executable, "-m", "snakemake", "--lint", "--configfile", "config/smoke.yaml"],
                            cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
