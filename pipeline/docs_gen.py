"""The documentation that is generated, not written (issue 54): ``loomlight docs`` writes it.

- ``docs/scenes.md``: every key of the files a user writes -- scene, tiling configuration, sweep,
  comparison, yarn and BCSDF presets -- with its type, default, allowed values and meaning, from their
  JSON Schemas (``schemas/<name>.schema.json``: ``description`` and ``default`` of every property), the
  scene's ``[render]`` table from the renderer registry (``pipeline.renderers.render_schema``) and the
  defaults the readers take from code (``code_defaults``: ``COMMON_DEFAULTS``, the camera's, the
  comparison's levels, the yarn presets'), so the page cannot drift from what is accepted.
- ``docs/methods/<page>.md`` (``PAGES``): the text between ``<!-- BEGIN GENERATED: settings -->`` and
  ``<!-- END GENERATED: settings -->`` -- the method's sources, ``--set`` keys, materials and shared
  settings from the registry, and the options of the commands that make its inputs from the command
  line itself -- and between the ``measurements`` markers a summary of the measured numbers. The rest of
  a page is written by hand; a missing page is created with a title and the two blocks.
- ``docs/measurements.md``: the benchmarks' results (``bench/results/<name>.json``, written by
  ``bench/run.py``) and the equal-error comparisons' summaries (``out/compare/<name>/convergence.json``,
  ``pipeline.runners.convergence_report``), with the date, machine and git revision, an anchor per
  method page (``measurements.md#prt``), per benchmark (``#bench-<name>``) and per comparison
  (``#compare-<name>``). What was not measured says so. ``make bench`` and ``make compare`` rewrite it;
  a rewrite that would change only its header (date, machine, revision) leaves the file as it is.

``check`` compares ``docs/scenes.md`` and the settings blocks with what would be generated (the
measurements depend on local results and are not checked). Everything here is plain Python: no kernel is
compiled, nothing is rendered.
"""
from __future__ import annotations

import ast
import datetime
import difflib
import json
import os
import platform
import re
import subprocess
from dataclasses import dataclass
from pathlib import Path

from .errors import LoomError

ROOT = Path(__file__).resolve().parents[1]
PARTS = ("scenes", "methods", "measurements")


# ------------------------------------------------------------------------------------------------ formatting
def _num(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        s = (f"{v:.1f}" if abs(v) < 1e3 else str(int(v)) if abs(v) < 1e5 else f"{v:g}") if v.is_integer() else repr(v)
        return s.replace("e+0", "e").replace("e+", "e").replace("e-0", "e-")
    return str(v)


def _value(v) -> str:
    """A value as it is written in TOML."""
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return _num(v)


def _md(text) -> str:
    """Plain text for markdown: ``<`` outside code spans escaped (``<view>`` is not an HTML tag)."""
    parts = str(text).split("`")
    return "`".join(p if i % 2 else p.replace("<", "&lt;") for i, p in enumerate(parts))


def _cell(text) -> str:
    """Text fit for one markdown table cell."""
    return _md(" ".join(str(text).split())).replace("|", "\\|")


def _table(headers, rows) -> list[str]:
    out = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    out += ["| " + " | ".join(_cell(c) for c in r) + " |" for r in rows]
    return out


def _plural(t: str) -> str:
    if t.startswith("array of"):
        return "arrays" + t[len("array"):]
    if " or " in t or t.endswith("s"):
        return t
    return t + "s"


# ------------------------------------------------------------------------------------------------ schemas
SCHEMA_DOCS = (   # (schema, anchor, title, where the files live and what reads them)
    ("scene", "scene", "Scene file",
     "`data/scenes/*.toml`; read by `loomlight ingest`, `render` and `fit-bysdf`, named by tilings, sweeps and "
     "comparisons"),
    ("tile-config", "tiling", "Tiling configuration", "`data/tilings/*.toml`; read by `loomlight tile`"),
    ("sweep", "sweep", "Sweep file", "`data/sweeps/*.toml`; read by `loomlight evaluate --sweep FILE` "
                                     "(`make sweep`, `make prt-sweep`, `make btf-sweep`)"),
    ("compare", "comparison", "Comparison file",
     "`data/compare/*.toml`; read by `loomlight evaluate --convergence FILE` (`make references`, `make compare`)"),
    ("yarn-preset", "yarn-preset", "Yarn preset", "`data/yarns/<name>.toml`; named by a scene's "
                                                   "`yarns.<group>.preset` or a tiling's `yarn.preset`"),
    ("bcsdf-preset", "bcsdf-preset", "BCSDF preset", "`data/bcsdf/<name>.toml` or a `.toml` file beside a scene; "
                                                     "named by `yarns.<group>.bcsdf` or `--bcsdf`"),
)

# the [render] keys render_schema() leaves undescribed and the render command has no option for
RENDER_NOTES = {
    "rr_depth": "Russian roulette from this path depth on",
    "tile_size": "side of the square image tiles the render loop hands to its threads, in pixels",
    "ground": "a ground plane under the cloth",
    "ground.height": "the plane's height (z)",
    "ground.albedo": "the plane's albedo",
}


def code_defaults() -> dict:
    """{(schema, table, dotted key): default} for defaults that live in code, not in a schema."""
    from .fibre_cache import DEFAULT_CACHE_MIB
    from .presets import DEFAULT_PRESET, DEFAULTS as PRESET_DEFAULTS, PACKING_FRACTION
    from .renderers import COMMON_DEFAULTS
    from .runners.compare_file import DEFAULT_EQUAL_TIME_SPP, DEFAULT_LEVELS
    from .scene import CAMERA_DEFAULTS

    d = {("scene", "", f"camera.{k}"): v for k, v in CAMERA_DEFAULTS.items()}
    d.update({("scene", "", f"render.{k}"): v for k, v in COMMON_DEFAULTS.items() if k not in ("width", "height")})
    d[("scene", "", "render.cache")] = DEFAULT_CACHE_MIB
    d[("scene", "", "render.ground.height")] = 0.0      # pipeline/scene.py: load_scene
    d[("scene", "", "render.ground.albedo")] = 0.5
    d[("compare", "", "compare.levels")] = list(DEFAULT_LEVELS)
    d[("compare", "", "compare.equal_time_spp")] = DEFAULT_EQUAL_TIME_SPP
    d.update({("yarn-preset", "", k): v for k, v in PRESET_DEFAULTS.items()})
    d[("yarn-preset", "", "packing_fraction")] = PACKING_FRACTION
    d[("scene", "yarn_type", "preset")] = DEFAULT_PRESET
    return d


def _render_option_help() -> dict:
    """{key: help} of the render command's options (``--max-depth`` -> ``max_depth``)."""
    cmd = _command(("render",))
    return {p.name: p.help for p in cmd.params if getattr(p, "help", None)}


def load_doc_schema(name: str) -> dict:
    """The schema as the readers validate against it (the scene's [render] table from the registry), its
    undescribed [render] keys described by the render command's options and ``RENDER_NOTES``."""
    from .schemas import load_schema

    schema = json.loads(json.dumps(load_schema(name)))   # a copy: load_schema's is cached and shared
    if name == "scene":
        from .renderers import source_help

        render = schema["properties"]["render"]
        helps = _render_option_help()
        for key, node in render["properties"].items():
            if "description" not in node:
                node["description"] = (source_help() if key == "source" else
                                       helps.get(key) or RENDER_NOTES.get(key, ""))
            for sub, sn in node.get("properties", {}).items():
                if isinstance(sn, dict) and "description" not in sn:
                    sn["description"] = RENDER_NOTES.get(f"{key}.{sub}", "")
    return schema


@dataclass
class Row:
    key: str
    type: str
    default: str
    allowed: str
    description: str


def _def_name(node) -> str | None:
    ref = node.get("$ref", "") if isinstance(node, dict) else ""
    return ref.split("/")[-1] if ref.startswith("#/$defs/") else None


def _resolve(root: dict, node):
    """``node`` with a local ``$ref`` replaced by its target; the node's own keys (description) win."""
    while isinstance(node, dict) and "$ref" in node:
        target = root
        for part in node["$ref"][2:].split("/"):
            target = target[part]
        node = {**target, **{k: v for k, v in node.items() if k != "$ref"}}
    return node


def _is_table(node) -> bool:
    return isinstance(node, dict) and ("properties" in node or "allOf" in node)


def _bounds(node) -> str:
    lo = ("[", node["minimum"]) if "minimum" in node else ("(", node["exclusiveMinimum"]) \
        if "exclusiveMinimum" in node else None
    hi = ("]", node["maximum"]) if "maximum" in node else (")", node["exclusiveMaximum"]) \
        if "exclusiveMaximum" in node else None
    if lo and hi:
        return f"{lo[0]}{_num(lo[1])}, {_num(hi[1])}{hi[0]}"
    if lo:
        return ("≥ " if lo[0] == "[" else "> ") + _num(lo[1])
    if hi:
        return ("≤ " if hi[0] == "]" else "< ") + _num(hi[1])
    return ""


def _type(root: dict, node, tables: dict) -> tuple[str, str]:
    """(type, allowed values) of a schema node, in words."""
    if node is True or node == {}:
        return "any", ""
    name = _def_name(node)
    node = _resolve(root, node)
    if name and _is_table(node):
        return f"table ([{tables[name][1]}](#{tables[name][0]}))", ""
    if "const" in node:
        return _type_of(node["const"]), f"`{_value(node['const'])}`"
    if "enum" in node:
        types = dict.fromkeys(_type_of(v) for v in node["enum"])
        return " or ".join(types), "one of " + ", ".join(f"`{_value(v)}`" for v in node["enum"])
    for key in ("oneOf", "anyOf"):
        if key in node:
            parts = [_type(root, n, tables) for n in node[key]]
            return " or ".join(dict.fromkeys(t for t, _ in parts)), "; ".join(a for _, a in parts if a)
    t = node.get("type")
    if isinstance(t, list):
        return " or ".join("nothing" if x == "null" else x for x in t), _bounds(node)
    if t == "array" or "items" in node or "prefixItems" in node:
        return _array_type(root, node, tables)
    if t == "object" or "properties" in node:
        return "table", ""
    allowed = [_bounds(node)] if _bounds(node) else []
    if "pattern" in node:
        allowed.append(f"matches `{node['pattern']}`")
    if "maxLength" in node:
        allowed.append(f"at most {node['maxLength']} characters")
    return (t or "any"), "; ".join(allowed)


def _type_of(v) -> str:
    return {bool: "boolean", int: "integer", float: "number", str: "string"}.get(type(v), "value")


def _array_type(root, node, tables) -> tuple[str, str]:
    n_min, n_max = node.get("minItems"), node.get("maxItems")
    if "prefixItems" in node:
        parts = [_type(root, n, tables) for n in node["prefixItems"]]
        allowed = "; ".join(f"item {i + 1} {a}" for i, (_, a) in enumerate(parts) if a)
        return "[" + ", ".join(t for t, _ in parts) + "]", allowed
    item_t, item_a = _type(root, node.get("items", True), tables)
    count = f"{n_min} " if n_min is not None and n_min == n_max else ""
    if item_t.startswith("table ("):   # an array of the tables a $defs entry describes
        typ = f"array of {count}tables {item_t[len('table '):]}"
    else:
        typ = f"array of {count}{_plural(item_t) if n_min != 1 or not count else item_t}"
    allowed = []
    if n_min != n_max:
        if n_min and n_max:
            allowed.append(f"{n_min} to {n_max} items")
        elif n_min:
            allowed.append(f"at least {n_min} item{'s' if n_min > 1 else ''}")
        elif n_max:
            allowed.append(f"at most {n_max} items")
    if item_a:
        allowed.append(item_a if item_a.startswith("each ") else f"each {item_a}")
    return typ, "; ".join(allowed)


def _rows(root: dict, node, prefix: str, tables: dict, defaults: dict, schema: str, table: str,
          condition: str = "") -> list[Row]:
    """One row per key of the table ``node`` (nested tables and arrays of tables after their key, dotted)."""
    node = _resolve(root, node)
    rows = []
    required = set(node.get("required", ()))
    for key, sub in node.get("properties", {}).items():
        if sub is True:
            continue
        path = f"{prefix}{key}"
        res = _resolve(root, sub)
        typ, allowed = _type(root, sub, tables)
        if (schema, table, path) in defaults:
            default = f"`{_value(defaults[(schema, table, path)])}`"
        elif isinstance(res, dict) and "default" in res:
            default = f"`{_value(res['default'])}`"
        else:
            default = "**required**" if key in required else "—"
        desc = res.get("description", "") if isinstance(res, dict) else ""
        rows.append(Row(f"`{path}`", typ, default, allowed, f"{condition}{desc}"))
        if _def_name(sub) and _is_table(res):
            continue   # documented once, in its own table
        if _is_table(res):
            rows += _rows(root, res, f"{path}.", tables, defaults, schema, table)
        items = res.get("items") if isinstance(res, dict) else None
        if isinstance(items, dict) and not _def_name(items) and _is_table(_resolve(root, items)):
            rows += _rows(root, items, f"{path}[].", tables, defaults, schema, table)
    for branch in node.get("allOf", ()):
        if "if" in branch and "then" in branch:
            cond = " and ".join(f"{k} = {_value(v.get('const'))}"
                                for k, v in branch["if"].get("properties", {}).items())
            then = {**branch["then"], "required": [r for r in branch["then"].get("required", ())]}
            rows += _rows(root, then, prefix, tables, defaults, schema, table, condition=f"*{cond}*: ")
    return rows


def _def_tables(root: dict, anchor: str) -> dict:
    """{def name: (anchor, title)} of the schema's $defs that are tables."""
    return {name: (f"{anchor}-{name.replace('_', '-')}", name.replace("_", " "))
            for name, node in root.get("$defs", {}).items() if _is_table(node)}


def _schema_section(name: str, anchor: str, title: str, where: str, defaults: dict) -> list[str]:
    root = load_doc_schema(name)
    tables = _def_tables(root, anchor)
    headers = ("key", "type", "default", "allowed", "meaning")
    out = [f'<a id="{anchor}"></a>', "", f"## {title}", "",
           f"{where}. Schema: `schemas/{name}.schema.json`.", ""]
    if root.get("description"):
        out += [_md(" ".join(root["description"].split())), ""]
    out += _table(headers, [(r.key, r.type, r.default, r.allowed, r.description)
                            for r in _rows(root, root, "", tables, defaults, name, "")])
    for def_name, (def_anchor, def_title) in tables.items():
        node = root["$defs"][def_name]
        out += ["", f'<a id="{def_anchor}"></a>', "", f"### {title}: {def_title}", ""]
        if node.get("description"):
            out += [_md(" ".join(node["description"].split())) + ".", ""]
        out += _table(headers, [(r.key, r.type, r.default, r.allowed, r.description)
                                for r in _rows(root, node, "", tables, defaults, name, def_name)])
    return out + [""]


def scenes_md() -> str:
    """The text of ``docs/scenes.md``."""
    defaults = code_defaults()
    out = ["# File formats: scenes, tilings, sweeps, comparisons and presets", "",
           "<!-- Generated by `loomlight docs` from schemas/*.schema.json, the renderer registry and the readers' "
           "defaults (pipeline/docs_gen.py). Do not edit: change the schema, then run `make docs`. -->", "",
           "Every file is TOML. A key `a.b` is key `b` of the table `[a]`; `a[].b` is key `b` of every `[[a]]` "
           "table (an array of tables). *Default* is what a reader takes when the key is absent (— : nothing, "
           "the key is optional and its absence means what the meaning says); *allowed* is what the schema "
           "accepts: `[a, b]` a closed range, `(a, b]` open at a. An unknown key, a value of the wrong type or "
           "out of range is refused with one line naming the file and the key.", ""]
    out += [f"- [{title}](#{anchor}): {where}" for _, anchor, title, where in SCHEMA_DOCS] + [""]
    for name, anchor, title, where in SCHEMA_DOCS:
        out += _schema_section(name, anchor, title, where, defaults)
    return "\n".join(out).rstrip("\n") + "\n"


# ------------------------------------------------------------------------------------------------ method pages
@dataclass(frozen=True)
class Page:
    """A method page: the registry methods it documents, the commands that make their inputs, the
    benchmarks that measure them."""
    name: str
    title: str
    methods: tuple
    commands: tuple
    benchmarks: tuple


PAGES = {p.name: p for p in (
    Page("volpath", "volpath: procedural fibres as a volume", ("volpath",), (("tables",), ("voxelize",)),
         ("volpath", "lookup")),
    Page("fiberpath", "fiberpath: explicit fibres, path traced", ("fiberpath", "fiberpath_shell"), (("realize",),),
         ("fiberpath", "mitsuba")),
    Page("prt", "prt: precomputed light transport", ("prt",), (("tile",), ("precompute", "svf"),
                                                              ("precompute", "iirtf")), ("precompute",)),
    Page("btf", "btf: fitted cloth textures", ("btf",), (("precompute", "btf"),), ("btf",)),
    Page("bysdf", "bysdf: the yarn-level model", ("bysdf",), (("fit-bysdf",),), ("bysdf",)),
)}
# options every stage command has: said once, not in every table
PLUMBING = ("help", "force", "budget", "threads", "scheduler", "workers", "threads_per_worker")
SHARED_OPTION = {"width": ("camera.width", "--width"), "height": ("camera.height", "--height")}


def _command(path: tuple):
    """The click command ``loomlight <path>``."""
    from .cli import command

    cmd = command()
    for p in path:
        cmd = cmd.commands[p]
    return cmd


def _annotation_type(ann) -> str:
    import typing

    args = typing.get_args(ann)
    if typing.get_origin(ann) in (list, typing.List) and args:
        return _annotation_type(args[0])
    if typing.get_origin(ann) is tuple and args:
        return " ".join(_annotation_type(a) for a in args)
    return {int: "integer", float: "number", str: "text", Path: "path", bool: "flag"}.get(ann, "value")


def _param_type(p) -> str:
    if getattr(p, "is_flag", False):
        return "flag"
    typ = f"`{p.metavar}`" if p.metavar else _annotation_type(getattr(getattr(p, "type_descriptor", None),
                                                                      "annotation", None))
    return typ + (" (repeatable)" if getattr(p, "multiple", False) else "")


def _param_default(p) -> str:
    if p.required:
        return "**required**"
    if getattr(p, "is_flag", False):
        return "off"
    if p.default is None or p.default == () or p.default == []:
        return "—"
    return f"`{_value(p.default)}`"


def command_table(path: tuple) -> list[str]:
    cmd = _command(path)
    args = [p for p in cmd.params if p.param_type_name == "argument"]
    opts = [p for p in cmd.params if p.param_type_name != "argument" and p.name not in PLUMBING]
    usage = " ".join(["loomlight", *path, *(a.name.upper() for a in args), "[OPTIONS]"])
    summary = (cmd.help or "").strip().split("\n\n")[0]
    out = [f"**`{usage}`**: {_md(' '.join(summary.split()))}", ""]
    rows = [(f"`{a.name.upper()}`", "argument", "**required**", getattr(a, "help", "") or "") for a in args]
    rows += [(", ".join(f"`{o}`" for o in [*p.opts, *p.secondary_opts]), _param_type(p), _param_default(p),
              p.help or "") for p in opts]
    plumbing = [f"`--{n.replace('_', '-')}`" for n in PLUMBING[1:] if any(p.name == n for p in cmd.params)]
    out += _table(("option", "takes", "default", "meaning"), rows)
    if plumbing:
        out += ["", f"Also {', '.join(plumbing)} (`loomlight {' '.join(path)} --help`)."]
    return out + [""]


def _method_section(m) -> list[str]:
    from .renderers import CLI_INPUTS, COMMON_DEFAULTS

    def inp(i):
        opt = f"--{i.option}" if i.option in CLI_INPUTS else f"--set {i.option}="
        return f"`{opt}` {i.what}"

    out = [f"#### `loomlight render SCENE --method {m.name}`", "", f"{m.summary[0].upper()}{m.summary[1:]}.", ""]
    out += _table(("`--source`", "reads", "what it is"),
                  [(f"`{s.name}`" + (" (default)" if s.name == m.default_source else ""),
                    "; ".join(inp(i) for i in s.inputs), s.help) for s in m.sources])
    if m.settings:
        out += ["", "Method settings, `--set KEY=VALUE` (repeatable; a sweep's or comparison's method takes them in "
                    "its `args`):", ""]
        out += _table(("key", "values", "meaning"),
                      [(f"`{s.key}`", ", ".join(f"`{c}`" for c in s.choices) if s.choices else "—", s.help)
                       for s in m.settings])
    if m.materials:
        out += ["", f"Fibre material `--material`: {' or '.join(f'`{x}`' for x in m.materials)} "
                    f"(default `{m.materials[0]}`)."]
    render = _command(("render",))
    options = {p.name: p.opts[0] for p in render.params if p.opts}
    rows = []
    for key in COMMON_DEFAULTS:
        scene_key, _ = SHARED_OPTION.get(key, (f"render.{key}", None))
        own = dict(m.defaults).get(key)
        rows.append((f"`{key}`", f"`{_value(m.default(key))}`" + (" (this method's)" if own is not None else ""),
                     f"`{scene_key}`", f"`{options[key]}`" if key in options else "—"))
    out += ["", "Shared settings: the command line, else the scene, else these defaults "
                "(`pipeline.renderers.COMMON_DEFAULTS`):", ""]
    out += _table(("setting", "default", "scene key", "command line"), rows)
    return out + [""]


def settings_block(page: Page) -> str:
    """The settings block of a method page, from the registry and the commands' options."""
    from .renderers import METHODS

    out = ["<!-- generated by `loomlight docs` from the renderer registry (pipeline/renderers/__init__.py) and "
           "the commands' options; edit those and run `make docs`, not this block -->", ""]
    for name in page.methods:
        out += _method_section(METHODS[name])
    if page.commands:
        out += ["Its inputs:", ""]
        for path in page.commands:
            out += command_table(path)
    return "\n".join(out).rstrip("\n") + "\n"


def _markers(name: str) -> tuple[str, str]:
    return f"<!-- BEGIN GENERATED: {name} -->", f"<!-- END GENERATED: {name} -->"


def read_block(text: str, name: str, path=None) -> str | None:
    """The text between a block's markers (None when the page has no such block)."""
    begin, end = _markers(name)
    i, j = text.find(begin), text.find(end)
    if i < 0 and j < 0:
        return None
    if i < 0 or j < i or text.count(begin) > 1 or text.count(end) > 1:
        raise LoomError(path, f"{name} block", f"expected one {begin!r} followed by one {end!r}")
    return text[i + len(begin):j].strip("\n") + "\n"


def replace_block(text: str, name: str, content: str, path=None) -> str:
    """``text`` with the block ``name`` holding ``content`` (appended at the end when it has no such block)."""
    begin, end = _markers(name)
    block = f"{begin}\n{content.rstrip(chr(10))}\n{end}"
    if read_block(text, name, path) is None:
        return text.rstrip("\n") + f"\n\n{block}\n"
    i, j = text.find(begin), text.find(end)
    return text[:i] + block + text[j + len(end):]


def new_page(page: Page) -> str:
    """A method page that does not exist yet: its title and the two generated blocks."""
    s, m = _markers("settings"), _markers("measurements")
    return (f"# {page.title}\n\n## Settings\n\n{s[0]}\n{s[1]}\n\n## Measurements\n\n{m[0]}\n{m[1]}\n")


# ------------------------------------------------------------------------------------------------ measurements
@dataclass
class Measurements:
    header: list            # lines: date, machine, revision
    bench: dict             # name -> (results dict or None, file date or None, one-line summary)
    compare: dict           # stem -> (convergence.json dict or None, file date or None)
    bench_record: str       # bench/results/summary.md's "Machine:" line, or ""


def _file_date(p: Path) -> str:
    return datetime.datetime.fromtimestamp(p.stat().st_mtime, datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")


def machine() -> str:
    """CPU model, cores, memory and system of this machine."""
    model = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    model = model or platform.processor() or platform.machine() or "unknown CPU"
    mem = ""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                mem = f", {int(line.split()[1]) / 2**20:.0f} GiB memory"
    except OSError:
        pass
    return (f"{model}, {os.cpu_count()} cores{mem}, {platform.system()} {platform.release()}, "
            f"Python {platform.python_version()}")


def git_revision(root: Path = ROOT) -> str:
    try:
        rev = subprocess.run(["git", "-C", str(root), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                             text=True, timeout=30, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=30, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown (not a git checkout)"
    return rev + (" (with uncommitted changes)" if dirty else "")


def _bench_summary(path: Path) -> str:
    try:
        doc = ast.get_docstring(ast.parse(path.read_text())) or ""
    except (OSError, SyntaxError):
        return ""
    return " ".join(doc.split("\n\n")[0].split())


KEPT = ", kept from the page's previous version"   # a benchmark section this run has no result for


def kept_benchmarks(text: str) -> dict[str, tuple[dict, str]]:
    """The measured benchmark sections of a measurements page (``measurements_md``'s text): name ->
    (its flattened numbers as the page prints them, when and where it was measured: the section's date and
    the machine, from the section itself when it was kept before, else from the page's header)."""
    out = {}
    host = re.search(r"^- Machine: (.+)$", text, re.M)
    body = text.split("\n## Benchmarks", 1)[-1].split("\n## ", 1)[0] if "\n## Benchmarks" in text else ""
    for part in body.split('<a id="bench-')[1:]:
        name = part.split('"', 1)[0]
        m = re.search(r"^Measured (.+?)(?:" + re.escape(KEPT) + r" \(on (.+)\))?\.$", part, re.M)
        rows = [ln for ln in part.splitlines() if ln.startswith("| `")]
        if not m or not rows:
            continue
        res = {}
        for ln in rows:
            key, value = ln[2:-2].split(" | ", 1)
            res[key.strip("`")] = value.replace("\\|", "|")
        where = m.group(2) or (host.group(1) if host else "another machine")
        out[name] = (res, f"{m.group(1)}{KEPT} (on {where})")
    return out


def load_measurements(bench_results: Path, compare_dir: Path, bench_dir: Path | None = None,
                      compare_files=None, now: str | None = None, host: str | None = None,
                      revision: str | None = None, previous: Path | None = None) -> Measurements:
    """What ``measurements_md`` reports: every benchmark of ``bench_dir`` (``bench_*.py``) and every result in
    ``bench_results``; every comparison file (default ``data/compare/*.toml`` but make demo's
    ``demo_quick``) and every ``compare_dir/<name>/convergence.json``. Missing directories are no results.
    ``previous`` (the page as it stands): a benchmark without a result here keeps the numbers and date the
    page had for it, marked as kept (``make compare`` alone must not erase what ``make bench`` measured).
    Comparisons are never kept: their references are tied to the code that made them."""
    bench_dir = bench_dir if bench_dir is not None else ROOT / "bench"
    if compare_files is None:
        compare_files = [p for p in sorted((ROOT / "data" / "compare").glob("*.toml")) if p.stem != "demo_quick"]
    bench = {p.stem[len("bench_"):]: (None, None, _bench_summary(p))
             for p in sorted(Path(bench_dir).glob("bench_*.py"))}
    for p in sorted(Path(bench_results).glob("*.json")) if Path(bench_results).is_dir() else ():
        try:
            res = json.loads(p.read_text())
        except (OSError, json.JSONDecodeError):
            continue
        if isinstance(res, dict):
            bench[p.stem] = (res, _file_date(p), bench.get(p.stem, (None, None, ""))[2])
    if previous is not None and Path(previous).is_file():
        for name, (res, date) in kept_benchmarks(Path(previous).read_text()).items():
            if bench.get(name, (None,))[0] is None and name != COMPILE_REPORT:
                bench[name] = (res, date, bench.get(name, (None, None, ""))[2])
    compare = {Path(f).stem: (None, None) for f in compare_files}
    for p in sorted(Path(compare_dir).glob("*/convergence.json")) if Path(compare_dir).is_dir() else ():
        try:
            doc = json.loads(p.read_text())
        except (OSError, json.JSONDecodeError):
            continue
        if isinstance(doc, dict) and isinstance(doc.get("methods"), dict):
            compare[p.parent.name] = (doc, _file_date(p))
    record = ""
    summary = Path(bench_results) / "summary.md"
    if summary.is_file():
        record = next((ln[len("Machine:"):].strip() for ln in summary.read_text().splitlines()
                       if ln.startswith("Machine:")), "")
    now = now or datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    header = [f"- Generated: {now}", f"- Machine: {host or machine()}", f"- Revision: {revision or git_revision()}"]
    if record:
        header.append(f"- The benchmarks' own record (`bench/results/summary.md`): {record}")
    return Measurements(header, bench, compare, record)


def _flat(d: dict, prefix: str = "") -> list[tuple[str, object]]:
    out = []
    for k, v in d.items():
        if isinstance(v, dict):
            out += _flat(v, f"{prefix}{k}.")
        else:
            out.append((f"{prefix}{k}", v))
    return out


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, (list, dict)):
        s = json.dumps(v, default=str)
        return s if len(s) <= 120 else s[:117] + "..."
    return str(v)


HEADLINE = re.compile(r"(_per_s|_per_s_per_core|fps|speedup|speed_ratio|_met)$|target")


def _headline(res: dict) -> list[tuple[str, object]]:
    return [(k, v) for k, v in _flat(res) if HEADLINE.search(k) and not isinstance(v, (list, dict))][:12]


def _pct(v) -> str:
    return f"{float(v):.0%}"


def _seconds(t) -> str:
    if t is None:
        return "-"
    return f"{t:.3g} s" if t < 100 else f"{t / 60:.3g} min"


def _level_text(d: dict) -> str:
    t, b = d.get("time_s"), d.get("bound", "")
    if t is None:
        return "not reached" + (" (floor)" if d.get("floor_blocks") else "")
    if b == ">":
        return f"> {_seconds(t)}" + (" (floor)" if d.get("floor_blocks") else "")
    return ("≤ " if b == "<=" else "") + _seconds(t)


def _speedup(s) -> str:
    if not s or s.get("value") is None:
        return "-"
    sym = {">=": "≥ ", "<=": "≤ ", "~": "~"}.get(s.get("bound", ""), "")
    return f"{sym}{s['value']:.3g}×"


def _bytes(n) -> str:
    if not isinstance(n, (int, float)):
        return "-"
    for unit, size in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{int(n)} B"


def _compare_rows(doc: dict, only=None) -> list[tuple]:
    ref = doc.get("reference", {}).get("method")
    levels = [f"{v:g}" for v in doc.get("levels", [])]
    rows = []
    for name, s in doc["methods"].items():
        if only is not None and s.get("method", name) not in only:
            continue
        se = s.get("speedup_at_equal_error")
        sp = "reference method" if name == ref else (
            f"{_speedup(se)} at {_pct(se['level'])}" if se else "-")
        floor = f"{s['floor']:.3f} ± {s.get('floor_se', 0):.3f}" if isinstance(s.get("floor"), (int, float)) else "-"
        times = "; ".join(f"{_pct(lv)}: {_level_text(s['levels'][lv])}" for lv in levels if lv in s.get("levels", {}))
        rows.append((name, s.get("method", name), floor, times, sp, _bytes(s.get("peak_memory_bytes"))))
    return rows


def _compare_section(stem: str, doc, date) -> list[str]:
    out = [f'<a id="compare-{stem}"></a>', "", f"### {stem}", ""]
    if doc is None:
        return out + [f"Not measured in this run (`make compare` writes `out/compare/{stem}/convergence.json` from "
                      f"`data/compare/{stem}.toml`).", ""]
    ref = doc.get("reference", {})
    if doc.get("description"):
        out += [" ".join(str(doc["description"]).split()), ""]
    out += [f"Measured {date}. Reference: {ref.get('method', '?')}, {ref.get('spp', '?')} spp from "
            f"{ref.get('batches', '?')} batches ({_seconds(ref.get('render_time_s'))} of rendering), relative "
            f"standard error of the cloth's mean {ref.get('mean_error', float('nan')):.4f}"
            + ("" if ref.get("targets_met", True) else " (its targets were not met)") + ". Error: relative RMSE "
            "over cloth pixels against the reference, its noise subtracted, fitted as E² = b² + c/t; times are "
            "render kernels only.", ""]
    out += _table(("method", "renderer", "bias floor b", "time to each error level", "speed-up at equal error",
                   "peak memory"), _compare_rows(doc))
    targets = doc.get("targets") or []
    if targets:
        out += ["", "Targets: " + "; ".join(
            f"{t['method']} ≥ {t['target']:g}× at equal error: "
            + ("met" if t.get("met") else f"not met{': ' + t['why'] if t.get('why') else ''}")
            for t in targets) + "."]
    return out + [""]


def _bench_section(name: str, res, date, summary: str) -> list[str]:
    out = [f'<a id="bench-{name}"></a>', "", f"### {name}", ""]
    if summary:
        out += [f"`bench/bench_{name}.py`: {summary}", ""]
    if res is None:
        return out + [f"Not measured in this run (`make bench` writes `bench/results/{name}.json`).", ""]
    out += [f"Measured {date}.", ""]
    out += _table(("quantity", "value"), [(f"`{k}`", _fmt(v)) for k, v in _flat(res)])
    return out + [""]


COMPILE_REPORT = "compile"   # bench/results/compile.json, written by make compile-report
COMPILE_ROWS = 25            # kernels listed on the page (the json has them all)


def _compile_section(res, date) -> list[str]:
    """make compile-report's numbers: the cold-cache compile time per part and the kernels that cost most."""
    out = ['<a id="compile"></a>', "", "## Compilation on a cold cache", "",
           "`make compile-report` (`bench/compile_report.py`): numba's compile events while the demo's commands "
           "and the heaviest test files run on empty caches; core-seconds are summed over processes.", ""]
    if not isinstance(res, dict) or not isinstance(res.get("totals"), dict):
        return out + ["Not measured in this run (`make compile-report` writes `bench/results/compile.json`).", ""]
    m = res.get("machine", {})
    out += [f"Measured {date} (demo: {m.get('demo', '?')}; tests: {' '.join(m.get('tests') or []) or '?'}).", ""]
    out += _table(("part", "compile, core-minutes", "wall", "processes", "kernels", "compilations"),
                  [(name, f"{t['compile_core_s'] / 60:.2f}", _seconds(t["wall_s"]), t["processes"], t["kernels"],
                    t["compilations"]) for name, t in res["totals"].items()])
    rows = []
    for k in (res.get("kernels") or [])[:COMPILE_ROWS]:
        top = (k.get("by_signature") or [{}])[0]
        asked = "; ".join((top.get("asked_by") or [])[:2])
        rows.append((f"`{k['kernel']}`", f"{k['self_s']:.1f}", k["signatures"], k["recompiled"], _cell(asked)))
    out += ["", "Kernels typed more than one way first, then kernels compiled by more than one process with the "
                "same signature, then by seconds (without the kernels compiled inside them):", ""]
    out += _table(("kernel", "seconds", "signatures", "compiled again", "asked by (first signature)"), rows)
    return out + [""]


def method_summary(page: Page, data: Measurements, link: str) -> list[str]:
    """The measured numbers of one method page: its comparisons' rows and its benchmarks' headline numbers;
    ``link`` is the path of measurements.md from where the text goes."""
    out = []
    only = set(page.methods)
    rows = []
    for stem, (doc, _) in data.compare.items():
        if doc is not None:
            ref = doc.get("reference", {}).get("method", "?")
            rows += [(f"[{stem}]({link}#compare-{stem})", ref, r[0], *r[2:5]) for r in _compare_rows(doc, only)]
    if rows:
        out += ["Equal-error comparisons (`make compare`):", ""]
        out += _table(("comparison", "reference method", "method", "bias floor b", "time to each error level",
                       "speed-up at equal error"), rows)
        out += [""]
    benches = [(b, data.bench.get(b, (None, None, ""))) for b in page.benchmarks]
    brow = [(f"[{b}]({link}#bench-{b})", f"`{k}`", _fmt(v))
            for b, (res, _, _) in benches if res for k, v in _headline(res)]
    if brow:
        out += ["Benchmarks (`make bench`):", ""]
        out += _table(("benchmark", "quantity", "value"), brow)
        out += [""]
    missing = [b for b, (res, _, _) in benches if res is None]
    if missing or not rows:
        what = ([f"benchmark{'s' if len(missing) > 1 else ''} {', '.join(missing)}"] if missing else []) + \
               ([] if rows else ["equal-error comparisons"])
        out += [f"Not measured in this run: {' and '.join(what)}.", ""]
    return out


def measurements_block(page: Page, data: Measurements) -> str:
    out = ["<!-- generated by `loomlight docs` from bench/results and out/compare (make bench, make compare); "
           "do not edit this block -->", "",
           f"From [measurements](../measurements.md#{page.name}) (date, machine and revision there).", ""]
    out += method_summary(page, data, "../measurements.md")
    return "\n".join(out).rstrip("\n") + "\n"


def measurements_md(data: Measurements) -> str:
    out = ["# Measurements", "",
           "<!-- Generated by `loomlight docs` (make bench and make compare run it) from bench/results/*.json and "
           "out/compare/*/convergence.json. Do not edit. -->", "",
           "The numbers `make bench` and `make compare` last wrote on this machine; the method pages and the README "
           "quote them.", ""]
    out += data.header + [""]
    out += ["## By method", ""]
    for page in PAGES.values():
        out += [f'<a id="{page.name}"></a>', "", f"### {page.name}", "", f"Method page: [{page.name}](methods/"
                                                                          f"{page.name}.md).", ""]
        out += method_summary(page, data, "")
    out += ["## Benchmarks", "", "`make bench` (`bench/run.py`): each `bench/bench_<name>.py` writes "
                                 "`bench/results/<name>.json`.", ""]
    for name, (res, date, summary) in sorted(data.bench.items()):
        if name != COMPILE_REPORT:
            out += _bench_section(name, res, date, summary)
    out += _compile_section(*data.bench.get(COMPILE_REPORT, (None, None, ""))[:2])
    out += ["## Comparisons", "", "`make compare` (`loomlight evaluate --convergence`): every method against a "
                                  "converged reference, error against time; the reports are "
                                  "`out/compare/<name>/report.html`.", ""]
    for stem, (doc, date) in sorted(data.compare.items()):
        out += _compare_section(stem, doc, date)
    return "\n".join(out).rstrip("\n") + "\n"


def _body(text: str) -> str:
    """measurements.md without its header (date, machine, revision)."""
    i = text.find("\n## ")
    return text[i:] if i >= 0 else text


# ------------------------------------------------------------------------------------------------ writing
def _write(path: Path, text: str) -> bool:
    """Write ``text`` to ``path`` when it differs (atomically: a temporary file renamed over it)."""
    if path.is_file() and path.read_text() == text:
        return False
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)
    return True


def generate(root: Path = ROOT, parts=PARTS, bench_results: Path | None = None, compare_dir: Path | None = None,
             data: Measurements | None = None) -> list[Path]:
    """Write the generated documentation under ``root/docs``; returns the files that changed."""
    docs = Path(root) / "docs"
    changed = []
    if "scenes" in parts and _write(docs / "scenes.md", scenes_md()):
        changed.append(docs / "scenes.md")
    if "measurements" in parts and data is None:
        data = load_measurements(bench_results or Path(root) / "bench" / "results",
                                 compare_dir or Path(root) / "out" / "compare", previous=docs / "measurements.md")
    if "measurements" in parts:
        path = docs / "measurements.md"
        text = measurements_md(data)
        if not (path.is_file() and _body(path.read_text()) == _body(text)) and _write(path, text):
            changed.append(path)
    if "methods" in parts or "measurements" in parts:
        for page in PAGES.values():
            path = docs / "methods" / f"{page.name}.md"
            text = path.read_text() if path.is_file() else new_page(page)
            new = text
            if "methods" in parts:
                new = replace_block(new, "settings", settings_block(page), path)
            if "measurements" in parts:
                new = replace_block(new, "measurements", measurements_block(page, data), path)
            if _write(path, new):
                changed.append(path)
    return changed


def _diff(old: str, new: str, what: str) -> str:
    lines = list(difflib.unified_diff(old.splitlines(), new.splitlines(), "committed", "generated", n=0, lineterm=""))
    changed = sum(1 for ln in lines if ln[:1] in "+-" and not ln.startswith(("+++", "---")))
    shown = [f"    {ln}" for ln in lines[2:8]]
    return "\n".join([f"{what}: {changed} line(s) differ from what `loomlight docs` generates"] + shown)


def check(root: Path = ROOT) -> list[str]:
    """What is stale: one summary per file or block that differs from what would be generated (scenes.md and
    the settings blocks; the measurements depend on local results). Empty when everything is current."""
    docs = Path(root) / "docs"
    problems = []
    scenes = docs / "scenes.md"
    if not scenes.is_file():
        problems.append(f"{scenes}: missing")
    elif scenes.read_text() != scenes_md():
        problems.append(_diff(scenes.read_text(), scenes_md(), str(scenes)))
    for page in PAGES.values():
        path = docs / "methods" / f"{page.name}.md"
        if not path.is_file():
            problems.append(f"{path}: missing")
            continue
        block = read_block(path.read_text(), "settings", path)
        want = settings_block(page)
        if block is None:
            problems.append(f"{path}: no settings block ({_markers('settings')[0]} ... {_markers('settings')[1]})")
        elif block != want:
            problems.append(_diff(block, want, f"{path} (settings block)"))
    return problems
