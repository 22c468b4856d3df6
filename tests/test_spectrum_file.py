"""Issue 34, items 10-12 and 19: one spectrum reader for every command, refusing negative, complex and malformed
input with the file, line and column named; the mesh-spectrum -> fit round trip."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from shspec.cli import main
from shspec.errors import InvalidArgumentError
from shspec.spectrum_file import check_spectrum_path, read_spectrum, read_spectrum_file
from shspec.fitting.targets import parse_target

LAM = [float(l * (l + 1)) for l in range(6) for _ in range(2 * l + 1)]  # the round sphere, degrees 0-5


def _topology(path, capsys):
    code = main(["topology", "--target", f"spectrum:{path}", "--json"])
    out, err = capsys.readouterr()
    return code, (json.loads(out) if code == 0 else err)


@pytest.mark.parametrize("name, text", [
    ("one.txt", "\n".join(map(str, LAM))),
    ("line.txt", " ".join(map(str, LAM))),
    ("line.csv", ",".join(map(str, LAM))),
    ("two.txt", "\n".join(f"{i:5d}  {v}" for i, v in enumerate(LAM))),
    ("plain.csv", "\n".join(f"{i},{v}" for i, v in enumerate(LAM))),
    ("header.csv", "index,eigenvalue\n" + "\n".join(f"{i},{v}" for i, v in enumerate(LAM))),
    ("bom.csv", "\ufeffeigenvalue\n" + "\n".join(map(str, LAM))),
    ("bom.json", "\ufeff" + json.dumps({"eigenvalues": LAM})),
])
def test_every_format_gives_the_same_spectrum_to_fit_and_topology(tmp_path, name, text, capsys):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    np.testing.assert_array_equal(read_spectrum(path), LAM)
    assert parse_target(f"spectrum:{path}", lmax=4, numeig=len(LAM), lmax_factor=2).numeig == len(LAM)
    code, out = _topology(path, capsys)
    assert code == 0 and out["numeig"] == len(LAM), out


def test_a_three_column_file_is_index_eigenvalue_error_for_every_command(tmp_path, capsys):
    path = tmp_path / "three.txt"
    path.write_text("\n".join(f"{i} {v} {0.01 * v}" for i, v in enumerate(LAM)))
    spectrum = read_spectrum_file(path)
    np.testing.assert_array_equal(spectrum.eigenvalues, LAM)
    np.testing.assert_allclose(spectrum.errors, 0.01 * np.array(LAM))
    np.testing.assert_array_equal(parse_target(f"spectrum:{path}", lmax=4, numeig=len(LAM), lmax_factor=2).eigenvalues,
                                  LAM)
    code, out = _topology(path, capsys)
    assert code == 0 and out["numeig"] == len(LAM)
    header = tmp_path / "named.csv"
    header.write_text("k,lambda,sigma\n" + "\n".join(f"{i},{v},0.5" for i, v in enumerate(LAM)))
    np.testing.assert_array_equal(read_spectrum_file(header).errors, [0.5] * len(LAM))


@pytest.mark.parametrize("error, words", [(0.0, "error 3 is 0 (line 4, column 3) for the eigenvalue 2"),
                                          (3.0, "error 3 is 3 (line 4, column 3) for the eigenvalue 2")])
def test_one_rule_for_the_error_column_with_file_and_line(tmp_path, capsys, error, words):
    """Issue 50, item 20: a zero error passed the reader and topology and was refused by fit without the file and
    line; an error above its eigenvalue made topology fail on "relative_noise", a parameter never set."""
    errors = [0.0] + [0.01 * v for v in LAM[1:]]  # the error of lambda_0 may be 0: lambda_0 = 0 is exact
    errors[3] = error
    path = tmp_path / "errs.txt"
    path.write_text("\n".join(f"{i} {v} {e}" for i, (v, e) in enumerate(zip(LAM, errors))))
    with pytest.raises(InvalidArgumentError, match=re.escape(f"{path}: {words}")):
        read_spectrum_file(path)
    with pytest.raises(InvalidArgumentError, match=re.escape(words)):
        parse_target(f"spectrum:{path}", lmax=4, numeig=len(LAM), lmax_factor=2)
    code, err = _topology(path, capsys)
    assert code == 1 and words in err and "relative_noise" not in err


@pytest.mark.parametrize("text, message", [
    ("0\n1\nnan\n3\n", r"eigenvalue 2 is nan \(line 3, column 1\)"),
    ("0 0\n1 2\n2 abc\n", r"line 3, column 2: 'abc' is not a number"),
    ("# c\n0\n2\n6\n5\n", r"not ascending: eigenvalue 3 \(5\) is below eigenvalue 2 \(6\) \(line 5, column 1\)"),
    ("name,nvertices,lambda_1,lambda_max\nb,42,1,9\n", "a table of meshes"),
    ("a,b\n1,2\n", r"line 1: no eigenvalue column among a, b"),
    ("0 1\n1 2 3\n", "line 2 has 3 columns, the lines before it 2"),
    ("2.0 1\n3.0 2\n6 3\n", "column 1 is not an index"),
    ("# only comments\n", "holds no eigenvalues"),
])
def test_text_errors_name_the_file_line_and_column(tmp_path, text, message, capsys):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(InvalidArgumentError, match=message) as info:
        read_spectrum(path)
    assert str(path) in str(info.value)
    code, err = _topology(path, capsys)
    assert code == 1 and "bad.txt" in err and "loadtxt" not in err


def test_a_directory_or_a_missing_file_is_named_before_reading(tmp_path):
    """Issue 50, item 21: 'shspec fit --target spectrum:DIR' said "no such file"; check_spectrum_path is what a
    command checks before its long work, with the reader's own words."""
    with pytest.raises(InvalidArgumentError, match=f"{re.escape(str(tmp_path))} is a directory, not a spectrum file"):
        check_spectrum_path(tmp_path)
    with pytest.raises(InvalidArgumentError, match="gone.txt: no such spectrum file$"):
        check_spectrum_path(tmp_path / "gone.txt")
    link = tmp_path / "link.txt"
    link.symlink_to(tmp_path / "gone.txt")
    with pytest.raises(InvalidArgumentError, match=r"no such spectrum file \(a symbolic link to .*gone.txt, which"):
        read_spectrum(link)


def test_a_json_object_with_the_wrong_key_names_its_keys(tmp_path):
    path = tmp_path / "s.json"
    path.write_text(json.dumps({"eigen": LAM}))
    with pytest.raises(InvalidArgumentError, match=r"needs an 'eigenvalues' list .*its keys: 'eigen'"):
        read_spectrum(path)
    path.write_text("[0, 1,")
    with pytest.raises(InvalidArgumentError, match=r"s.json: line 1, column 7: not valid JSON"):
        read_spectrum(path)


# item 10 ------------------------------------------------------------------------------------------------------

def test_a_negative_first_eigenvalue_is_refused_not_replaced_by_zero(tmp_path, capsys):
    path = tmp_path / "neg.txt"
    path.write_text("\n".join(map(str, [-5.0, *LAM[1:]])))
    with pytest.raises(InvalidArgumentError, match=r"eigenvalue 0 is -5 \(line 1, column 1\).*never negative"):
        parse_target(f"spectrum:{path}", lmax=4, numeig=5, lmax_factor=2)
    code, err = _topology(path, capsys)
    assert code == 1 and "never negative" in err
    np.save(tmp_path / "neg.npy", np.array([-5.0, 2.0, 6.0]))
    with pytest.raises(InvalidArgumentError, match=r"eigenvalue 0 is -5 \(entry 0\)"):
        read_spectrum(tmp_path / "neg.npy")


# item 11 (the spectrum part) ----------------------------------------------------------------------------------

def test_a_complex_npy_spectrum_is_refused(tmp_path):
    path = tmp_path / "c.npy"
    np.save(path, np.array(LAM) + 1j)
    with pytest.raises(InvalidArgumentError, match="complex"):
        read_spectrum(path)


# item 19 ------------------------------------------------------------------------------------------------------

def test_mesh_spectrum_out_file_round_trips_into_fit(tmp_path, capsys):
    from shspec.mesh.mesh_files import save_mesh
    from shspec.mesh.shapes import blob

    mesh = tmp_path / "m.obj"
    save_mesh(blob(1), mesh)
    out = tmp_path / "s.txt"
    assert main(["mesh-spectrum", str(mesh), "--numeig", "12", "--out", str(out), "--quiet"]) == 0
    assert out.is_file()
    printed = tmp_path / "printed.txt"
    assert main(["mesh-spectrum", str(mesh), "--numeig", "12"]) == 0
    printed.write_text(capsys.readouterr().out)
    np.testing.assert_allclose(read_spectrum(out), read_spectrum(printed), rtol=1e-14)
    target = parse_target(f"spectrum:{out}", lmax=4, numeig=12, lmax_factor=2)
    assert target.numeig == 12 and target.eigenvalues[0] == 0.0
    for suffix in ("csv", "json", "npy"):
        other = tmp_path / f"s.{suffix}"
        assert main(["mesh-spectrum", str(mesh), "--numeig", "12", "--out", str(other), "--quiet"]) == 0
        np.testing.assert_array_equal(read_spectrum(other), read_spectrum(out))
