""".ssp archives: a packed scene loads like the loose one; unsafe members are refused unpacked."""

from __future__ import annotations

import shutil
import stat
import zipfile
from pathlib import Path

import pytest

from master.fmubuild import fmu_path
from master.scenario import ScenarioError, load, validate

SCENE = Path(__file__).parent / "scenarios" / "oscillator"


@pytest.fixture(autouse=True)
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Unpack into this test's folder, not the shared temporary one."""
    folder = tmp_path / "cache"
    monkeypatch.setenv("MULTIRATE_MASTER_CACHE", str(folder))
    return folder


def pack(path: Path, members: dict[str, bytes], links: dict[str, str] | None = None) -> Path:
    with zipfile.ZipFile(path, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)
        for name, target in (links or {}).items():
            info = zipfile.ZipInfo(name)
            info.external_attr = (stat.S_IFLNK | 0o777) << 16
            zf.writestr(info, target)
    return path


def oscillator_members() -> dict[str, bytes]:
    """The oscillator scene with mass1's FMU packed inside (resources/msd.fmu)."""
    ssd = (SCENE / "oscillator.ssd").read_text().replace('source="msd"', 'source="resources/msd.fmu"')
    return {
        "SystemStructure.ssd": ssd.encode(),
        "mass1.ssv": (SCENE / "mass1.ssv").read_bytes(),
        "coupling.ssv": (SCENE / "coupling.ssv").read_bytes(),
        "resources/msd.fmu": fmu_path("msd").read_bytes(),
    }


def test_packed_scene_loads_like_the_loose_one(tmp_path: Path, cache: Path):
    archive = pack(tmp_path / "oscillator.ssp", oscillator_members())
    packed, loose = load(archive), load(SCENE / "oscillator.ssd")
    assert packed.path == archive.resolve()
    m1 = packed.components[0]
    assert m1.fmu_path.is_relative_to(cache) and m1.fmu_path.name == "msd.fmu"
    assert m1.fmu_path.read_bytes() == fmu_path("msd").read_bytes()
    assert [c.parameters for c in packed.components] == [c.parameters for c in loose.components]
    assert (packed.connections, packed.macro_step, packed.stop_time) == (
        loose.connections,
        loose.macro_step,
        loose.stop_time,
    )
    assert load(archive).components[0].fmu_path == m1.fmu_path  # unpacked once, reused


def test_problems_inside_an_archive_name_archive_and_member(tmp_path: Path):
    members = oscillator_members()
    members["mass1.ssv"] = members["mass1.ssv"].replace(b'name="m"', b'name="mass"')
    archive = pack(tmp_path / "scene.ssp", members)
    (problem,) = validate(archive)
    assert problem.file == f"{archive}!/mass1.ssv"
    assert problem.element == 'ssv:Parameter "mass"' and 'has no "mass"' in problem.message


@pytest.mark.parametrize(
    "member, reason",
    [
        ("../escape.txt", "escapes the archive"),
        ("resources/../../escape.txt", "escapes the archive"),
        ("/tmp/escape.txt", "absolute member path"),
        ("link", "symbolic link member"),
    ],
)
def test_unsafe_members_are_rejected_and_nothing_is_unpacked(
    tmp_path: Path, cache: Path, member: str, reason: str
):
    members = oscillator_members()
    links = {}
    if member == "link":
        links[member] = "/etc/passwd"
    else:
        members[member] = b"not for outside"
    archive = pack(tmp_path / "evil.ssp", members, links)
    problems = validate(archive)
    assert len(problems) == 1
    assert problems[0].file == str(archive)
    assert problems[0].element == f'member "{member}"'
    assert reason in problems[0].message
    assert not cache.exists() or not any(cache.iterdir())
    assert not (tmp_path / "escape.txt").exists() and not Path("/tmp/escape.txt").exists()
    with pytest.raises(ScenarioError):
        load(archive)


def test_source_may_not_leave_the_archive(tmp_path: Path):
    members = oscillator_members()
    members["SystemStructure.ssd"] = members["SystemStructure.ssd"].replace(
        b'source="resources/msd.fmu"', b'source="../msd.fmu"'
    )
    shutil.copy(fmu_path("msd"), tmp_path / "msd.fmu")
    (problem,) = validate(pack(tmp_path / "scene.ssp", members))
    assert problem.element == 'ssd:Component "mass1"' and "points outside the archive" in problem.message


def test_archive_without_ssd_or_not_a_zip(tmp_path: Path):
    (problem,) = validate(pack(tmp_path / "empty.ssp", {"readme.txt": b"nothing"}))
    assert "has no SystemStructure.ssd at its root" in problem.message
    junk = tmp_path / "junk.ssp"
    junk.write_bytes(b"this is not a zip archive")
    (problem,) = validate(junk)
    assert problem.file == str(junk) and "not a readable .ssp (zip) archive" in problem.message


def _damage(archive: Path, member: str, how: str) -> None:
    """Mark `member` encrypted, give it an unknown compression method, or corrupt its data."""
    data = bytearray(archive.read_bytes())
    with zipfile.ZipFile(archive) as zf:
        info = zf.getinfo(member)
    local = info.header_offset
    central = data.find(b"PK\x01\x02")  # the central directory entry of `member`
    while data[central + 46 : central + 46 + len(member)] != member.encode():
        central = data.find(b"PK\x01\x02", central + 4)
    if how == "encrypted":
        for at in (local + 6, central + 8):  # general purpose flag: bit 0
            data[at] |= 0x1
    elif how == "method":
        for at in (local + 8, central + 10):  # compression method 99 (AES, unknown here)
            data[at : at + 2] = (99).to_bytes(2, "little")
    else:  # the deflate stream itself
        start = local + 30 + int.from_bytes(data[local + 26 : local + 28], "little")
        start += int.from_bytes(data[local + 28 : local + 30], "little")
        data[start : start + 16] = b"\xff" * 16
    archive.write_bytes(bytes(data))


@pytest.mark.parametrize(
    "how, said", [("encrypted", "encrypted member"), ("method", "compression method"), ("deflate", "damaged")]
)
def test_damaged_archives_are_reported_at_validate(tmp_path: Path, how, said):
    archive = tmp_path / "oscillator.ssp"
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in oscillator_members().items():
            zf.writestr(name, data)
    _damage(archive, "mass1.ssv", how)
    problems = validate(archive)
    assert any(said in str(p) for p in problems), [str(p) for p in problems]


def test_the_unpacked_archives_are_evicted_beyond_the_cache_budget(tmp_path: Path, cache: Path, monkeypatch):
    from master.scenario import archive as arch

    monkeypatch.setattr(arch, "CACHE_BYTES", 3 * len(fmu_path("msd").read_bytes()))
    for i in range(6):  # six different archives (the ssd differs), each about one FMU in size
        members = oscillator_members()
        members["SystemStructure.ssd"] += f"<!-- {i} -->".encode()
        assert validate(pack(tmp_path / f"s{i}.ssp", members)) == []
    kept = [d for d in cache.iterdir() if not d.name.startswith(".")]
    assert 1 <= len(kept) <= 3


def test_a_doctype_is_refused(tmp_path: Path):
    ssd = (SCENE / "oscillator.ssd").read_text()
    evil = ssd.replace(
        "<ssd:SystemStructureDescription",
        '<!DOCTYPE x [<!ENTITY e "0.01">]>\n<ssd:SystemStructureDescription',
        1,
    )
    (tmp_path / "x.ssd").write_text(evil.replace('macroStep="0.01"', 'macroStep="&e;"'))
    for f in ("mass1.ssv", "coupling.ssv"):
        shutil.copy(SCENE / f, tmp_path / f)
    problems = validate(tmp_path / "x.ssd")
    assert len(problems) == 1 and "DOCTYPE" in str(problems[0])


def test_a_source_name_too_long_for_the_file_system(tmp_path: Path):
    ssd = (SCENE / "oscillator.ssd").read_text().replace('source="msd"', f'source="{"m" * 300}.fmu"')
    (tmp_path / "x.ssd").write_text(ssd)
    for f in ("mass1.ssv", "coupling.ssv"):
        shutil.copy(SCENE / f, tmp_path / f)
    problems = validate(tmp_path / "x.ssd")
    assert any("not a usable file name" in str(p) for p in problems), [str(p) for p in problems]


def test_a_parameter_file_name_too_long_is_one_problem_at_its_binding(tmp_path: Path):
    """A ParameterBinding source= of 302 characters (a mutation campaign's find): one problem naming
    the file, the binding and what is wrong, not an OSError (File name too long)."""
    ssd = (SCENE / "oscillator.ssd").read_text()
    assert 'source="mass1.ssv"' in ssd
    (tmp_path / "x.ssd").write_text(ssd.replace('source="mass1.ssv"', f'source="{"p" * 298}.ssv"'))
    shutil.copy(SCENE / "coupling.ssv", tmp_path / "coupling.ssv")
    problems = [str(p) for p in validate(tmp_path / "x.ssd")]
    (bad,) = [p for p in problems if "usable" in p]
    assert bad.startswith(f"{tmp_path / 'x.ssd'}:") and "ssd:ParameterBinding" in bad, bad
    assert f'source "{"p" * 60}..." (302 characters): not a usable file name (File name too long)' in bad
    with pytest.raises(ScenarioError):
        load(tmp_path / "x.ssd")


def test_a_zip_bomb_is_refused_unpacked(tmp_path: Path, cache: Path):
    members = oscillator_members()
    members["resources/zeros.bin"] = bytes(100 << 20)  # 100 MiB of zeros pack into about 100 KiB
    archive = tmp_path / "bomb.ssp"
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    problems = validate(archive)
    assert any("times" in str(p) and "unpacks" in str(p) for p in problems), [str(p) for p in problems]
    assert not cache.exists() or not any(d for d in cache.iterdir() if not d.name.startswith("."))


@pytest.mark.parametrize("how", ["traversal", "deflate"])
def test_a_damaged_or_unsafe_fmu_is_reported_at_validate(tmp_path: Path, how):
    """One zip check for .ssp and .fmu archives, at validate: a member path leaving the archive,
    or data that does not read back, in the FMU of a component."""
    fmu = tmp_path / "msd.fmu"
    with zipfile.ZipFile(fmu_path("msd")) as src, zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            dst.writestr(item.filename, src.read(item))
        if how == "traversal":
            dst.writestr("../escaped.txt", "x")
    if how == "deflate":
        _damage(fmu, "binaries/linux64/msd.so", "deflate")
    for f in SCENE.glob("*.ssv"):
        shutil.copy(f, tmp_path / f.name)
    ssd = (SCENE / "oscillator.ssd").read_text().replace('source="msd"', 'source="msd.fmu"')
    (tmp_path / "oscillator.ssd").write_text(ssd)
    problems = [str(p) for p in validate(tmp_path / "oscillator.ssd")]
    said = "escapes the archive" if how == "traversal" else "damaged"
    assert any(said in p and "mass1" in p for p in problems), problems
