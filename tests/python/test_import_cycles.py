"""scripts/import-cycles: its resolver on small synthetic source trees, and the check itself on the
repository's src/ (so CI runs it through scripts/test's python part)."""

from __future__ import annotations

import importlib.machinery
import importlib.util
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "import-cycles"


def load():
    loader = importlib.machinery.SourceFileLoader("import_cycles", str(SCRIPT))
    spec = importlib.util.spec_from_loader("import_cycles", loader)
    mod = importlib.util.module_from_spec(spec)
    loader.exec_module(mod)
    return mod


ic = load()


def tree(tmp_path, files, lib_name="demo"):
    """Writes {path under src/: text} and returns (edges, cycles) of it."""
    src = tmp_path / "src"
    for rel, text in files.items():
        p = src / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    _, edges, cycles = ic.find_cycles(src, lib_name)
    return edges, cycles


def names(edges, a, b):
    return sorted(edges.get(f"src/{a}", {}).get(f"src/{b}", {}))


def test_a_cycle_between_siblings_is_found_with_the_names_each_side_takes(tmp_path):
    edges, cycles = tree(tmp_path, {
        "lib.rs": "pub mod a;\npub mod b;\n",
        "a.rs": "use crate::b::Foo;\npub fn bar() {}\n",
        "b.rs": "pub struct Foo;\npub fn f() { crate::a::bar() }\n",
    })
    assert cycles == [["src/a.rs", "src/b.rs"]]
    assert names(edges, "a.rs", "b.rs") == ["Foo"]
    assert names(edges, "b.rs", "a.rs") == ["bar"]


def test_no_cycle_exits_0_and_a_cycle_exits_1_listing_it(tmp_path, capsys):
    src = tmp_path / "src"
    src.mkdir()
    (src / "lib.rs").write_text("pub mod a;\npub mod b;\n")
    (src / "a.rs").write_text("use crate::b::Foo;\n")
    (src / "b.rs").write_text("pub struct Foo;\n")
    assert ic.main(["--src", str(src)]) == 0
    assert capsys.readouterr().out == "import-cycles: none among 3 files\n"
    (src / "b.rs").write_text("pub struct Foo;\nuse super::a::*;\n")
    assert ic.main(["--src", str(src)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "import-cycles: 1 cycle among 3 files"
    assert "  src/a.rs -> src/b.rs: Foo" in out
    assert "  src/b.rs -> src/a.rs: *" in out


def test_a_declaration_is_not_an_import_but_a_re_export_is(tmp_path):
    files = {
        "lib.rs": "pub mod m;\n",
        "m/mod.rs": "mod child;\npub struct Y;\n",
        "m/child.rs": "use super::Y;\npub struct X;\n",
    }
    edges, cycles = tree(tmp_path, files)
    assert names(edges, "m/mod.rs", "m/child.rs") == []
    assert cycles == []
    files["m/mod.rs"] = "mod child;\npub use child::X;\npub struct Y;\n"
    edges, cycles = tree(tmp_path, files)
    assert names(edges, "m/mod.rs", "m/child.rs") == ["X"]
    assert cycles == [["src/m/child.rs", "src/m/mod.rs"]]


def test_an_a_rs_with_a_directory_of_children(tmp_path):
    edges, cycles = tree(tmp_path, {
        "lib.rs": "pub mod a;\n",
        "a.rs": "pub mod b;\npub use self::b::{B as Bee, c::C};\n",
        "a/b.rs": "pub mod c;\npub struct B;\n",
        "a/b/c.rs": "pub struct C;\n",
    })
    assert names(edges, "a.rs", "a/b.rs") == ["B"]
    assert names(edges, "a.rs", "a/b/c.rs") == ["C"]
    assert cycles == []


def test_group_imports_resolve_each_path_to_the_deepest_module_file(tmp_path):
    edges, _ = tree(tmp_path, {
        "lib.rs": "pub mod a;\npub mod x;\n",
        "a/mod.rs": "pub mod b;\npub fn top() {}\n",
        "a/b.rs": "pub mod d;\npub struct C;\n",
        "a/b/d.rs": "pub struct E;\n",
        "x.rs": "use crate::a::{top, b::{self, C, d::E}};\nuse std::{fmt, io::Read};\n",
    })
    assert names(edges, "x.rs", "a/mod.rs") == ["top"]
    assert names(edges, "x.rs", "a/b.rs") == ["C", "b"]
    assert names(edges, "x.rs", "a/b/d.rs") == ["E"]
    assert sorted(edges["src/x.rs"]) == ["src/a/b.rs", "src/a/b/d.rs", "src/a/mod.rs"]


def test_inline_paths_in_code(tmp_path):
    edges, cycles = tree(tmp_path, {
        "lib.rs": "pub mod can;\npub mod daemon;\n",
        "can/mod.rs": "pub mod messages;\n",
        "can/messages.rs": (
            "pub struct DctSensors;\nimpl DctSensors { pub const CYCLE_MS: u32 = 10; }\n"
        ),
        "daemon/mod.rs": "pub mod plant;\npub mod x;\n",
        "daemon/x.rs": "pub fn f() {}\n",
        "daemon/plant.rs": (
            "use crate::can::messages;\n"
            "fn g() -> u32 {\n"
            "    super::x::f();\n"
            "    let v: Vec<u8> = Vec::new();\n"
            "    messages::DctSensors::CYCLE_MS + crate::can::messages::DctSensors::CYCLE_MS\n"
            "}\n"
        ),
    })
    assert names(edges, "daemon/plant.rs", "daemon/x.rs") == ["f"]
    assert names(edges, "daemon/plant.rs", "can/messages.rs") == ["DctSensors", "messages"]
    assert cycles == []


def test_comments_strings_and_chars_are_ignored(tmp_path):
    edges, cycles = tree(tmp_path, {
        "lib.rs": "pub mod a;\npub mod b;\n",
        "a.rs": "pub fn f() {}\n",
        "b.rs": (
            "//! See [`crate::a::f`].\n"
            "// use crate::a::f;\n"
            "/* crate::a::f() /* nested */ crate::a::f() */\n"
            "fn g<'x>(s: &'x str) -> char {\n"
            "    let _ = \"crate::a::f()\";\n"
            "    let _ = r#\"crate::a::f() \"quoted\" \"#;\n"
            "    let _ = b\"crate::a::f\";\n"
            "    let _ = '\"'; let _ = '\\''; let _ = b'\"';\n"
            "    'c'\n"
            "}\n"
        ),
    })
    assert edges["src/b.rs"] == {}
    assert cycles == []


def test_test_modules_self_super_and_the_binary_crate(tmp_path):
    edges, cycles = tree(tmp_path, {
        "lib.rs": "pub mod a;\npub mod b;\n",
        "a.rs": (
            "pub fn f() {}\n"
            "#[cfg(test)]\nmod tests {\n    use super::*;\n    use crate::b::helper;\n}\n"
        ),
        "b.rs": "pub fn helper() {}\n",
        "main.rs": "mod cli;\nfn main() { cli::run() }\n",
        "cli/mod.rs": "pub fn run() { demo::a::f(); crate::cli::run(); }\n",
    })
    # `use super::*` in a.rs's test module is a.rs itself: no edge
    assert sorted(edges["src/a.rs"]) == ["src/b.rs"]
    assert edges["src/a.rs"]["src/b.rs"] == {"helper": (5, True)}
    assert names(edges, "main.rs", "cli/mod.rs") == ["run"]
    assert names(edges, "cli/mod.rs", "a.rs") == ["f"]
    assert cycles == []


def test_exported_macros_live_where_they_are_defined(tmp_path):
    edges, _ = tree(tmp_path, {
        "lib.rs": "pub mod util;\npub mod b;\n",
        "util.rs": (
            "#[macro_export]\nmacro_rules! table { () => { $crate::util::f() }; }\n"
            "pub fn f() {}\n"
        ),
        "b.rs": "crate::table!();\n",
    })
    assert names(edges, "b.rs", "util.rs") == ["table!"]


def test_src_has_no_import_cycle():
    """No import cycle between the files of src/ (issue 43): the script on the real tree exits 0."""
    out = subprocess.run([sys.executable, str(SCRIPT)], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.startswith("import-cycles: none among "), out.stdout
