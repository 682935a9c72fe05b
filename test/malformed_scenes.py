"""Malformed scene files, shared by the core's and the node's bad-input tests: each must be refused
with one message naming the file."""

from pathlib import Path

from cloth_sim.scene import MAX_SCENE_BYTES

SECRET = "hunter2-do-not-print"
GOOD = "grid: {rows: 4, cols: 4, spacing: 0.1}\n"

#: name -> bytes of a malformed scene file (each must be refused with one message naming the file)
CORPUS = {
    "empty": b"",
    "only_comment": b"# nothing\n",
    "null": b"null\n",
    "a_list": b"- 1\n- 2\n",
    "a_string": b"hello\n",
    "a_number": b"42\n",
    "binary": bytes(range(256)) * 4,
    "not_utf8": GOOD.encode() + b"name: \xff\xfe\n",
    "utf16": GOOD.encode("utf-16"),
    "syntax_error": f"grid: {{rows: 4, cols: [\n{SECRET}: 1\n".encode(),
    "tab_indent": f"grid:\n\trows: 4\n{SECRET}: 1\n".encode(),
    "alias_bomb": (
        b"a: &a [x, x, x, x, x, x, x, x, x]\n"
        + b"".join(
            f"{chr(98 + i)}: &{chr(98 + i)} [*{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, "
            f"*{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, "
            f"*{chr(97 + i)}]\n".encode()
            for i in range(8)
        )
        + GOOD.encode()
    ),
    "deep_nesting": b"grid: " + b"[" * 5000 + b"]" * 5000 + b"\n",
    "deep_mapping": b"grid:\n" + b"".join(b"  " * i + b"a:\n" for i in range(1, 60)) + b"\n",
    "huge": GOOD.encode() + b"name: '" + b"x" * (MAX_SCENE_BYTES + 10) + b"'\n",
    "integer_key": b"grid: {1: 16, cols: 4, spacing: 0.1}\n",
    "null_key": b"grid: {rows: 4, cols: 4, spacing: 0.1}\n~: 3\n",
    "list_key": b"grid: {rows: 4, cols: 4, spacing: 0.1}\n? [1, 2]\n: 3\n",
    "unknown_field": GOOD.encode() + b"colour: red\n",
    "grid_not_mapping": b"grid: 16\n",
    "rows_string": b"grid: {rows: many, cols: 4, spacing: 0.1}\n",
    "rows_float": b"grid: {rows: 4.5, cols: 4, spacing: 0.1}\n",
    "rows_600": b"grid: {rows: 600, cols: 4, spacing: 0.1}\n",
    "rows_bool": b"grid: {rows: true, cols: 4, spacing: 0.1}\n",
    "spacing_1e308": b"grid: {rows: 4, cols: 4, spacing: 1e308}\n",
    "spacing_nan": b"grid: {rows: 4, cols: 4, spacing: .nan}\n",
    "dt_tiny": GOOD.encode() + b"dt: 1e-9\n",
    "dt_inf": GOOD.encode() + b"dt: .inf\n",
    "gravity_short": GOOD.encode() + b"gravity: [0, -9.81]\n",
    "gravity_string": GOOD.encode() + b"gravity: down\n",
    "stiffness_negative": GOOD.encode() + b"stiffness: {structural: -1}\n",
    "stiffness_family": GOOD.encode() + b"stiffness: {stretch: 1}\n",
    "wind_list": GOOD.encode() + b"wind: [1, 2, 3]\n",
    "pinned_outside": GOOD.encode() + b"pinned: [[0, 99]]\n",
    "pinned_edges_bad": GOOD.encode() + b"pinned_edges: [top]\n",
    "integrator_unknown": GOOD.encode() + b"integrator: rk5\n",
    "model_unknown": GOOD.encode() + b"model: baraff\n",
    "strain_limit_big": GOOD.encode() + b"strain_limit: 100\n",
}


def write_corpus(folder: Path) -> dict:
    paths = {}
    for name, data in CORPUS.items():
        path = folder / f"{name}.yaml"
        path.write_bytes(data)
        paths[name] = path
    (folder / "a_directory.yaml").mkdir()
    paths["a_directory"] = folder / "a_directory.yaml"
    loop = folder / "loop.yaml"
    loop.symlink_to(loop)
    paths["link_loop"] = loop
    paths["missing"] = folder / "missing.yaml"
    return paths
