"""One version number everywhere: every package file and the newest CHANGELOG release say
`pd_core.__version__`."""

import re
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import pd_core

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = {
    "pd_bringup",
    "pd_core",
    "pd_interfaces",
    "pd_ocp_node",
    "pd_policy_node",
    "pd_ros_common",
    "pd_sim_node",
}
SETUP_VERSION = re.compile(r"""\bversion\s*=\s*["']([^"']+)["']""")


def _setup_py(path: Path) -> str:
    found = SETUP_VERSION.findall(path.read_text())
    assert len(found) == 1, f"{path}: {len(found)} version= arguments"
    return found[0]


def _package_xml(path: Path) -> str:
    version = ET.parse(path).getroot().findtext("version")
    assert version, f"{path}: no <version>"
    return version.strip()


def _pyproject(path: Path) -> str | None:
    return tomllib.loads(path.read_text()).get("project", {}).get("version")


def _stated_versions() -> dict[str, str]:
    """Every version a package file of the repository states, by path."""
    stated = {}
    for path in sorted(ROOT.glob("*/setup.py")):
        stated[str(path.relative_to(ROOT))] = _setup_py(path)
    for path in sorted(ROOT.glob("*/package.xml")):
        stated[str(path.relative_to(ROOT))] = _package_xml(path)
    for path in sorted([ROOT / "pyproject.toml", *ROOT.glob("*/pyproject.toml")]):
        if path.is_file() and (version := _pyproject(path)) is not None:
            stated[str(path.relative_to(ROOT))] = version
    return stated


def test_version_is_semver():
    assert re.fullmatch(r"\d+\.\d+\.\d+", pd_core.__version__), pd_core.__version__


def test_every_package_file_states_pd_core_version():
    stated = _stated_versions()
    xml_packages = {Path(p).parent.name for p in stated if p.endswith("package.xml")}
    setup_packages = {Path(p).parent.name for p in stated if p.endswith("setup.py")}
    assert xml_packages >= PACKAGES, sorted(PACKAGES - xml_packages)
    assert setup_packages >= PACKAGES - {"pd_interfaces"}, sorted(PACKAGES - setup_packages)
    assert len(stated) >= 7
    wrong = {path: v for path, v in stated.items() if v != pd_core.__version__}
    assert not wrong, f"not {pd_core.__version__}: {wrong}"


def test_newest_changelog_release_is_the_version():
    headings = re.findall(r"^## (\d+\.\d+\.\d+)\b", (ROOT / "CHANGELOG.md").read_text(), re.M)
    assert headings, "CHANGELOG.md has no '## X.Y.Z' release heading"
    assert headings[0] == pd_core.__version__, headings[:3]
