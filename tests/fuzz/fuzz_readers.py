"""Seeded fuzzing of fmugen's readers (issue 27): URDF files, component files, a scene's ``connect``
statements and the scene-analysis cache.

Each case mutates a valid input -- an element or key dropped or doubled, a value of the wrong type, a
number outside its format's grammar (``1_5``, Arabic-Indic digits, ``infinity``, hex floats), NaN and
infinities, huge values, non-ASCII text, names meant to break out into C or XML -- and reads it.  The
contract checked for every case:

* no crash: the reader succeeds or raises :class:`fmugen.errors.FmugenError` (the analysis cache never
  raises: a record it cannot trust is ignored, the scene analysed again);
* every refusal is one line naming the file (and, for the classes that target a field, that field);
* no silent-wrong: a mutation whose result is known must give it -- a number outside the grammar,
  NaN or infinity in a numeric field, a vector of the wrong length, a non-ASCII expression, a connect
  end that names nothing, an edited cache record: refused (never read as something else); a hostile
  name that is accepted reaches the model only as an identifier; a description with ``*/`` or ``]]>``
  reaches the C source and modelDescription.xml only escaped; a pair written the other way round gives
  the same connections; a cache record served is the record written, its FMU the FMU written.

Anything else is a *finding*, printed with the seed, surface, class and case number.

Short run (in the suite): ``tests/fuzz/test_fuzz_readers.py``.  Long run, with the counts per surface
and class: ``python tests/fuzz/fuzz_readers.py --cases 2000 --seed 1``.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import re
import sys
import tempfile
import traceback
from collections import defaultdict
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
LIBRARY = ROOT / "fmugen" / "components" / "library"
COMPONENTS = ("pd.toml", "spring_damper.toml", "stribeck.toml", "first_order_sensor.toml")

#: numbers float() or TOML read but the format's grammar does not hold
BAD_NUMBERS = ["1_5", "\u0663", "\u0661\u0662", "\uff11", "infinity", "nan", "inf", "-Infinity", "0x1p3", "0x10",
               "1,5", "1e", ".", "--1", "1.2.3", "1e1_0", "\u00b2", "1\u00a0", "+INF", "nAn"]
NON_FINITE = ["NaN", "INF", "-INF", "1e999", "-1e400"]
HUGE = ["1e300", "-1e300", "1e-300", "1.7976931348623157e308", "4.9e-324", "123456789012345678901234567890"]
WRONG_TYPE = ["abc", "true", "", " ", "[1]", "{}", "'1'"]
#: names meant to break out of an identifier, a C comment or string, or an XML attribute
HOSTILE_NAMES = ['a"b', "a'b", "x*/y", "x/*y", "</robot>", "a&b", "a<b", "${x}", "$(find x)", "a b", "", ".",
                 "__import__", "if", "int", "q_1", "\u202ename", "na\u00efve", "\uff4d", "x" * 200, "a\\b",
                 "a\nb", "1abc", "-x", "a;b", "a%sb"]
INJECT_TEXT = ['*/ int pwn; /*', ']]> <x/>', '" onload="x', "\\\" ); system(\"id\"); (\"", "??/ trigraph",
               "<!-- -->", "&amp; &#0;", "\u202e RLO", "%s%n", "\x7f"]

URDF = """<?xml version="1.0"?>
<robot name="fuzz_arm">
  <link name="base"/>
  <link name="upper">
    <inertial><origin xyz="0.01 0.02 0.2" rpy="0.1 0.2 0.3"/><mass value="2.0"/>
      <inertia ixx="0.03" ixy="0.001" ixz="-0.002" iyy="0.04" iyz="0.003" izz="0.02"/></inertial>
  </link>
  <link name="fore">
    <inertial><origin xyz="0.15 0 0.01"/><mass value="1.2"/>
      <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <link name="tool">
    <inertial><origin xyz="0.02 0.01 0.03" rpy="0.4 0 0"/><mass value="0.7"/>
      <inertia ixx="0.001" ixy="0.0001" ixz="0" iyy="0.002" iyz="0" izz="0.0015"/></inertial>
  </link>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/><origin xyz="0 0 0.3" rpy="0 0 0.2"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="40" velocity="3"/>
    <dynamics damping="0.5" friction="0"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="upper"/><child link="fore"/><origin xyz="0.05 0 0.4" rpy="0.3 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="20" velocity="3"/>
  </joint>
  <joint name="flange" type="fixed">
    <parent link="fore"/><child link="tool"/><origin xyz="0.3 0.01 -0.02" rpy="0.3 -0.2 0.5"/>
  </joint>
</robot>
"""
#: attributes that hold numbers (one, or a vector of three), as URDF defines them
URDF_NUMERIC = {"value": 1, "ixx": 1, "ixy": 1, "ixz": 1, "iyy": 1, "iyz": 1, "izz": 1, "lower": 1, "upper": 1,
                "effort": 1, "velocity": 1, "damping": 1, "friction": 1, "xyz": 3, "rpy": 3}

#: the rig of tests/test_scene_connect.py: component-file and built-in instances with connectors
RIG = """[scene]
name = "rig"
stop = 0.5
connect = {connect}
[instances]
gear = {{ type = "lib:gear_backlash" }}
load = {{ type = "lib:stribeck" }}
act = {{ type = "lib:hydraulic_actuator" }}
valve = {{ type = "servo_valve" }}
inert = {{ type = "joint_inertia" }}
"""
RIG_PAIRS = [["load.flange", "gear.load"], ["act.port", "valve.port"], ["act.flange", "inert.flange"]]
RIG_ENDS = ["load.flange", "gear.load", "act.port", "valve.port", "act.flange", "inert.flange", "gear.shaft",
            "valve.Q_L", "act.Q_L", "nosuch.port", "load.nosuch", "load", "load.", ".flange", "load.flange.x",
            "load.flange[1]", "arm.joint[0]", "arm.joint[99]", "load.phi", "inert.theta", "inert.tau"]

#: the smallest scene there is, for the analysis cache (its FMU is never compiled here: see _cache_setup)
CACHE_SCENE = """[scene]
name = "fz"
stop = 0.1
step = 1e-2
record = ["joint.theta", "joint.w"]
[instances]
joint = { type = "joint_inertia" }
"""

CLASSES = {
    "urdf": ["number", "non-finite", "huge", "count", "type", "drop", "dup", "name", "unicode", "xml"],
    "component": ["number", "equation-number", "non-finite", "huge", "type", "drop", "dup", "name", "unicode",
                  "inject"],
    "connect": ["end", "hostile-end", "shape", "dup", "swap", "drop"],
    "cache": ["truncate", "bitflip", "edit-value", "edit-type", "drop-key", "hostile-json", "not-utf8",
              "directory", "device", "big", "fmu-bytes", "fmu-missing", "forged-traversal", "forged-types",
              "reformat"],
}


def _toml_number(text: str) -> bool:
    """Whether ``text`` is a finite number in TOML's own grammar (``1_5`` and ``0x10`` are)."""
    import math
    import tomllib

    try:
        v = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return False
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _c_parts(src: str) -> tuple:
    """(the C code with comments and literals removed, the string literals, the // comments) of ``src``."""
    code, strings, lines = [], [], []
    i, n = 0, len(src)
    while i < n:
        if src.startswith("/*", i):
            j = src.find("*/", i + 2)
            i = n if j < 0 else j + 2
        elif src.startswith("//", i):
            j = src.find("\n", i)
            j = n if j < 0 else j
            lines.append(src[i:j])
            i = j
        elif src[i] in "\"'":
            q, j = src[i], i + 1
            while j < n and src[j] != q:
                j += 2 if src[j] == "\\" else 1
            (strings if q == '"' else code).append(src[i + 1:j])
            i = j + 1
        else:
            code.append(src[i])
            i += 1
    return "".join(code), strings, lines


def _diff(a: str, b: str) -> str:
    """The first changed region of ``b`` against ``a`` (for a finding's message)."""
    i = next((k for k, (x, y) in enumerate(zip(a, b)) if x != y), min(len(a), len(b)))
    j = 0
    while j < min(len(a), len(b)) - i and a[len(a) - 1 - j] == b[len(b) - 1 - j]:
        j += 1
    return f"...{b[max(0, i - 30):len(b) - j + 10]}..."


class Runner:
    def __init__(self, seed: int, workdir: Path):
        self.rng = random.Random(seed)
        self.seed = seed
        self.dir = Path(workdir)
        self.counts = {s: defaultdict(lambda: [0, 0, 0]) for s in CLASSES}  # class -> [cases, accepted, refused]
        self.findings = []
        self._cache = None

    # -- the contract --------------------------------------------------------------------------------------
    def _finding(self, surface, cls, n, text):
        self.findings.append(f"{surface}/{cls} #{n} (seed {self.seed}): {text}; case: {self.what[:200]!r}")

    verbose = False  # print every refusal (--verbose)
    what = ""  # the case's mutation, for its finding

    def _check(self, surface, cls, n, path, call, must_refuse=False, field=None, accepted=None):
        """Run ``call``; count it; a crash, a message of several lines or not naming ``path`` (and ``field``),
        or an acceptance of what ``must_refuse`` -- or that ``accepted(result)`` finds wrong -- is a finding."""
        from fmugen.errors import FmugenError

        c = self.counts[surface][cls]
        c[0] += 1
        try:
            result = call()
        except FmugenError as e:
            c[2] += 1
            msg = str(e)
            if self.verbose:
                print(f"  {surface}/{cls} #{n}: refused: {msg[:240]}")
            if "\n" in msg.strip():
                self._finding(surface, cls, n, f"a message of several lines: {msg[:200]!r}")
            if path is not None and str(path) not in msg:
                self._finding(surface, cls, n, f"the refusal does not name the file: {msg[:200]!r}")
            if field is not None and field not in msg:
                self._finding(surface, cls, n, f"the refusal does not name the field {field!r}: {msg[:200]!r}")
            return None
        except RecursionError:
            self._finding(surface, cls, n, "RecursionError")
            return None
        except Exception as e:  # noqa: BLE001 - any other exception is a finding
            tb = traceback.format_exc(limit=4).strip().splitlines()
            self._finding(surface, cls, n, f"{type(e).__name__}: {str(e)[:150]} at {' | '.join(tb[-3:])[:300]}")
            return None
        c[1] += 1
        if self.verbose:
            print(f"  {surface}/{cls} #{n}: accepted")
        if must_refuse:
            self._finding(surface, cls, n, f"silently accepted ({must_refuse})")
        elif accepted is not None:
            problem = accepted(result)
            if problem:
                self._finding(surface, cls, n, f"accepted, but {problem}")
        return result

    # -- URDF ----------------------------------------------------------------------------------------------
    def urdf(self, n: int) -> None:
        from fmugen.robot.urdf import load_urdf

        rng, cls = self.rng, self.rng.choice(CLASSES["urdf"])
        text, must, field = URDF, False, None
        attrs = [(m.start(), m.group(1), m.group(2)) for m in re.finditer(r'(\w+)="([^"]*)"', text)]
        numeric = [a for a in attrs if a[1] in URDF_NUMERIC]
        pos, attr, old = rng.choice(numeric)
        count = URDF_NUMERIC[attr]

        def put(new):
            start = text.index(f'{attr}="{old}"', pos)
            return text[:start] + f'{attr}="{new}"' + text[start + len(attr) + len(old) + 3:]

        def one_item(bad):
            items = old.split() if count == 3 else [old]
            items[rng.randrange(len(items))] = bad
            return " ".join(items)

        if cls == "number":
            text, must, field = put(one_item(rng.choice(BAD_NUMBERS))), "a number outside xs:double", attr
        elif cls == "non-finite":
            text, must, field = put(one_item(rng.choice(NON_FINITE))), "a non-finite number", attr
        elif cls == "huge":
            text = put(one_item(rng.choice(HUGE)))
        elif cls == "count":
            k = rng.choice([0, 2, 4] if count == 3 else [0, 2, 3])
            text, must, field = put(" ".join(["0.1"] * k)), f"{k} numbers where {count} belong", attr
        elif cls == "type":
            text, must, field = put(rng.choice(["abc", "true", "1 a 2", "[1]", "0.1;0.2", "1 2 3 4 5"])), \
                "text where a number belongs", attr
        elif cls in ("drop", "dup"):
            import xml.etree.ElementTree as ET

            root = ET.fromstring(URDF)  # the trusted template
            parents = [(p, c) for p in root.iter() for c in p]
            parent, child = rng.choice(parents)
            if cls == "drop":
                parent.remove(child)
            else:
                import copy

                parent.insert(list(parent).index(child), copy.deepcopy(child))
            text = ET.tostring(root, encoding="unicode")
        elif cls == "name":
            names = list(re.finditer(r'(name|link)="([^"]*)"', text))
            m = rng.choice(names)
            bad = rng.choice(HOSTILE_NAMES).replace('"', "&quot;").replace("<", "&lt;").replace("&b", "&amp;b")
            text = text[:m.start(2)] + bad + text[m.end(2):]
        elif cls == "unicode":
            if rng.random() < 0.5:
                text, must, field = put(one_item(rng.choice(["\u0663", "\uff11.5", "1\u06f5", "\u2212" + "1"]))), \
                    "non-ASCII digits", attr
            else:
                m = rng.choice(list(re.finditer(r'name="([^"]*)"', text)))
                text = text[:m.start(1)] + rng.choice(["\u00e9", "\u4e2d", "\uff41", "\u200b"]) + text[m.start(1):]
        else:  # xml
            k = rng.randrange(5)
            if k == 0:
                text = text[:rng.randrange(len(text))]
            elif k == 1:
                text = text.replace('<?xml version="1.0"?>', '<?xml version="1.0"?><!DOCTYPE r [<!ENTITY e "x">]>')
            elif k == 2:
                text = text.replace("<link name=\"base\"/>", "<a>" * 5000 + "</a>" * 5000 + '<link name="base"/>')
            elif k == 3:
                pos2 = rng.randrange(len(text))
                text = text[:pos2] + rng.choice(["\x00", "\x01", "&", "<", "]]>", "\ufffe"]) + text[pos2:]
            else:
                text = text.replace('name="fuzz_arm"', 'name="fuzz_arm" xmlns:xacro="x"') + "<xacro:x/>"
        self.what = _diff(URDF, text)
        path = self.dir / f"urdf_{n}.urdf"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        self._check("urdf", cls, n, path, lambda: load_urdf(path), must_refuse=must, field=field,
                    accepted=self._urdf_ok)

    @staticmethod
    def _urdf_ok(robot):
        import math

        from fmugen.errors import IDENTIFIER_PATTERN

        if not IDENTIFIER_PATTERN.match(robot.name):
            return f"the robot's name {robot.name!r} is no identifier"
        for p in robot.parameters:
            if not IDENTIFIER_PATTERN.match(p.name) or not p.name.isascii():
                return f"parameter name {p.name!r} is no C identifier"
            if p.value is not None and not math.isfinite(p.value):
                return f"parameter {p.name} = {p.value!r}"
        return None

    # -- component files -----------------------------------------------------------------------------------
    def component(self, n: int) -> None:
        from fmugen.components.equations import load_component

        rng, cls = self.rng, self.rng.choice(CLASSES["component"])
        base = rng.choice(COMPONENTS)
        lines = (LIBRARY / base).read_text().splitlines()
        must, field = False, None
        num_lines = [i for i, l in enumerate(lines) if re.search(r"\b(value|start|min|max|nominal) = -?[0-9.]", l)]
        eq_lines = [i for i, l in enumerate(lines) if re.match(r'\s*"[^"]*=[^"]*",?$', l)]

        def replace_number(i, new):
            m = rng.choice(list(re.finditer(r"\b(value|start|min|max|nominal) = (-?[0-9][0-9.eE+-]*)", lines[i])))
            lines[i] = lines[i][:m.start(2)] + new + lines[i][m.end(2):]
            return m.group(1)

        if cls == "number" and num_lines:  # a TOML value that is no TOML number: a syntax error or a string
            i = rng.choice(num_lines)
            bad = rng.choice(BAD_NUMBERS)
            field = None  # TOML syntax errors name the line, not the key
            new = rng.choice([bad, f'"{bad}"'])
            replace_number(i, new)
            must = "a number outside TOML's grammar (or a string where a number belongs)"
            if _toml_number(new):  # 1_5, 0x10 are TOML's own integers: a TOML number is fine
                must = False
        elif cls == "equation-number" and eq_lines:
            i = rng.choice(eq_lines)
            lits = list(re.finditer(r"(?<![A-Za-z_0-9.])[0-9]+(\.[0-9]*)?", lines[i]))
            bad = rng.choice(["1_5", "0x10", "0o7", "0b1", "1j", "1e999", "\u0663", "\uff11", "1e1_0"])
            if lits:
                m = rng.choice(lits)
                lines[i] = lines[i][:m.start()] + bad + lines[i][m.end():]
            else:
                lines[i] = lines[i].replace(' = ', f' = {bad}*', 1).replace(f"der({bad}*", "der(")
            must = "a literal outside the expression language's grammar"
        elif cls == "non-finite" and num_lines:
            i = rng.choice(num_lines)
            field = replace_number(i, rng.choice(["nan", "inf", "-inf", "+nan", "1e400"]))
            must = "a non-finite number"
        elif cls == "huge" and num_lines:
            replace_number(rng.choice(num_lines), rng.choice(HUGE))
        elif cls == "type":
            i = rng.randrange(len(lines))
            if " = " in lines[i]:
                k, _, _ = lines[i].partition(" = ")
                lines[i] = k + " = " + rng.choice(['"text"', "[1, 2]", "{ a = 1 }", "true", "1979-05-27", "[]"])
        elif cls == "drop":
            del lines[rng.randrange(len(lines))]
        elif cls == "dup":
            i = rng.randrange(len(lines))
            lines.insert(i, lines[i])
        elif cls == "name":  # a declared name (a key of a table) made hostile
            keyed = [i for i, l in enumerate(lines) if re.match(r"[A-Za-z_][A-Za-z0-9_]* = \{", l)]
            i = rng.choice(keyed)
            k = lines[i].split(" = ", 1)[0]
            bad = rng.choice(HOSTILE_NAMES)
            lines[i] = json.dumps(bad) + lines[i][len(k):]
            self._names_accepted = bad
        elif cls == "unicode" and eq_lines:
            i = rng.choice(eq_lines)
            m = re.match(r'(\s*")([^"]*)(")', lines[i])
            body = m.group(2)
            p = rng.randrange(len(body) + 1)
            ch = rng.choice(["\uff58", "\u00e9", "\u0663", "\u2212", "\u00a0", "\U0001d431", "\u200b"])
            lines[i] = m.group(1) + body[:p] + ch + body[p:] + lines[i][m.end(2):]
            must = "a non-ASCII character in an equation"
        else:  # inject: text that must reach C and XML only escaped
            cls = "inject"
            marker = rng.choice(INJECT_TEXT)
            i = next(i for i, l in enumerate(lines) if l.startswith("description = "))
            lines[i] = "description = " + json.dumps("fuzz " + marker)
        self.what = f"{base}: " + _diff((LIBRARY / base).read_text(), "\n".join(lines) + "\n")
        path = self.dir / f"component_{n}.toml"
        path.write_text("\n".join(lines) + "\n", encoding="utf-8", errors="surrogatepass")
        check = self._component_ok if cls == "inject" else self._component_names_ok
        self._check("component", cls, n, path, lambda: load_component(path), must_refuse=must, field=field,
                    accepted=check)

    @staticmethod
    def _component_names_ok(model):
        from fmugen.components.equations.file import language_identifier

        for g in (model.states, model.inputs, model.outputs, model.parameters):
            for v in g:
                if not language_identifier(v.name):
                    return f"the variable name {v.name!r} is no identifier of the language"
        return None

    @staticmethod
    def _component_ok(model):
        """The description reaches the C source and modelDescription.xml escaped: no comment or string of the
        C source ends early, the XML parses and gives the text back."""
        import defusedxml.ElementTree as DET

        from fmugen.codegen.c_code import generate_c
        from fmugen.fmi.model_description import model_description_xml

        problem = Runner._component_names_ok(model)
        if problem:
            return problem
        code, strings, line_comments = _c_parts(generate_c(model).source)
        for bad in ("pwn", "system(", "onload"):
            if bad in code:
                return f"{bad!r} reached the C code outside comments and strings"
        if any("??" in t for t in strings) or any("??/" in t or t.endswith("\\") for t in line_comments):
            return "a trigraph or line splice reached a C string or // comment"
        xml = model_description_xml(model, "{00000000-0000-0000-0000-000000000000}", "m")
        root = DET.fromstring(xml.encode("utf-8"))
        desc = root.get("description") or ""
        if model.description and not desc:
            return "the description is missing from modelDescription.xml"
        if "<x/>" in xml or 'onload="x' in xml:
            return "markup of the description reached modelDescription.xml unescaped"
        return None

    # -- connect -------------------------------------------------------------------------------------------
    def connect(self, n: int) -> None:
        from fmugen.scene import load_scene

        rng, cls = self.rng, self.rng.choice(CLASSES["connect"])
        pairs = [list(p) for p in RIG_PAIRS]
        must, raw = False, None
        expect = None
        if cls == "end":
            k, side = rng.randrange(len(pairs)), rng.randrange(2)
            pairs[k][side] = rng.choice(RIG_ENDS)
        elif cls == "hostile-end":
            k, side = rng.randrange(len(pairs)), rng.randrange(2)
            inst = pairs[k][side].split(".")[0]
            bad = rng.choice(HOSTILE_NAMES + INJECT_TEXT)
            pairs[k][side] = rng.choice([bad, f"{inst}.{bad}", f"{bad}.flange", f"{inst}.flange{bad}"])
            must = "a connect end that names no connector"
        elif cls == "shape":
            raw = rng.choice(['"load.flange"', '[["load.flange"]]', '[["a.b", "c.d", "e.f"]]', "[1, 2]",
                              '[[1, "gear.load"]]', '{ a = "b" }', '[["load.flange", ["gear.load"]]]',
                              '[[{ a = 1 }, "gear.load"]]', "[" * 400 + "]" * 400, '[["", ""]]', "true"])
            must = "a connect value of the wrong shape"
        elif cls == "dup":
            pairs.append(list(rng.choice(pairs)))
            must = "an input driven twice"
        elif cls == "swap":  # the same bonds written the other way round: the same connections
            for p in pairs:
                if rng.random() < 0.5:
                    p.reverse()
            expect = "base"
        else:  # drop: fewer bonds are fine (their inputs stay undriven)
            del pairs[rng.randrange(len(pairs))]
        text = RIG.format(connect=raw if raw is not None else json.dumps(pairs))
        self.what = f"connect = {text.splitlines()[3][10:]}"
        path = self.dir / f"connect_{n}.toml"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        field = "connect" if must else None

        def ok(scene):
            for b in scene.spec.bonds:
                for end in b.ends:
                    if end.split(".")[0] not in scene.spec.instances:
                        return f"the bond end {end!r} names no instance"
            if expect == "base":
                if self._rig_connections is None:
                    return None
                if set(scene.connections) != self._rig_connections:
                    return "the pairs written the other way round gave other connections"
            return None

        if expect == "base" and getattr(self, "_rig_connections", None) is None:
            base = self.dir / "connect_base.toml"
            base.write_text(RIG.format(connect=json.dumps(RIG_PAIRS)))
            self._rig_connections = set(load_scene(base).connections)
        self._check("connect", cls, n, path, lambda: load_scene(path), must_refuse=must, field=field, accepted=ok)

    _rig_connections = None

    # -- the analysis cache --------------------------------------------------------------------------------
    def _cache_setup(self):
        """A stored analysis of CACHE_SCENE written by the product's own :func:`store`, with a stand-in FMU
        file (the cache copies and digests FMUs, never opens them: no compiler needed)."""
        from fmugen.scene import load_scene
        from fmugen.scene import analysis_cache as ac
        from fmugen.scene.build import BuiltScene, FmuReport

        d = self.dir / "cache_case"
        d.mkdir(exist_ok=True)
        scene_path = d / "fz.toml"
        scene_path.write_text(CACHE_SCENE)
        scene = load_scene(scene_path)
        fmu_dir = d / "fmus"
        fmu_dir.mkdir(exist_ok=True)
        paths, reports = {}, {}
        for g in scene.groups:
            p = fmu_dir / f"{g}.fmu"
            p.write_bytes(b"PK\x03\x04 stand-in FMU " + g.encode() * 50)
            paths[g] = p
            reports[g] = FmuReport(g, p, tuple(scene.groups[g].members), 2, 2, 0, 2, {"evaluate": "3"}, 3, 1000,
                                   0.5, False, True)
        built = BuiltScene(scene, fmu_dir, reports, scene.cosim_system(paths), [], [], float("inf"), 1e-2)
        key = ac.analysis_key(scene_path)
        ac.store(key, scene, built)
        rec = ac._record_path(key)
        if not rec.is_file():
            raise RuntimeError("the analysis record was not stored")
        self._cache = (scene_path, key, rec, rec.read_bytes(), json.loads(rec.read_text()),
                       {g: paths[g].read_bytes() for g in paths})

    def cache(self, n: int) -> None:
        from fmugen.scene import analysis_cache as ac

        if self._cache is None:
            self._cache = "pending"
            self._cache_setup()
        scene_path, key, rec, raw, record, fmus = self._cache
        rng, cls = self.rng, self.rng.choice(CLASSES["cache"])
        folder = rec.with_suffix("")
        # restore the stored state, then damage it
        if rec.is_dir() or rec.is_symlink():
            (rec.rmdir() if rec.is_dir() and not rec.is_symlink() else rec.unlink())
        rec.write_bytes(raw)
        for g, b in fmus.items():
            (folder / f"{g}.fmu").write_bytes(b)
        changed = True
        if cls == "truncate":
            rec.write_bytes(raw[:rng.randrange(len(raw))])
        elif cls == "bitflip":
            b = bytearray(raw)
            i = rng.randrange(len(b))
            b[i] ^= 1 << rng.randrange(7)
            rec.write_bytes(bytes(b))
            changed = bytes(b) != raw
        elif cls in ("edit-value", "edit-type", "drop-key", "forged-traversal", "forged-types", "reformat"):
            r = json.loads(raw)
            if cls == "edit-value":
                target = rng.choice(["x0", "start", "default_step", "name"])
                if target == "x0" and r["x0"]:
                    r["x0"][rng.choice(sorted(r["x0"]))] += 0.5
                elif target == "start":
                    u = r["system"]["units"][0]
                    u["start_values"][rng.choice(sorted(u["start_values"]))] = 7.0
                elif target == "default_step":
                    r["default_step"] = 1.0
                else:
                    r["name"] = "other"
            elif cls == "edit-type":
                k = rng.choice(["fmus", "x0", "system", "spec", "inputs", "name", "initial_report"])
                r[k] = rng.choice([[], {}, None, 1, "x", [1, 2], {"a": [1]}])
            elif cls == "drop-key":
                del r[rng.choice(sorted(r))]
            elif cls == "forged-traversal":  # a consistent record an attacker wrote: a group escaping the folder
                g = next(iter(r["fmus"]))
                evil = rng.choice(["../evil", "/tmp/evil", "a/../../b", "..", "x\x00y"])
                r["fmus"][evil] = r["fmus"].pop(g)
                r["fmus"][evil]["report"]["group"] = evil
                for u in r["system"]["units"]:
                    u["name"] = evil
                r["digest"] = ac._seal(key, r)
            elif cls == "forged-types":
                k = rng.choice(["units", "couplings", "recorded", "start_values", "report"])
                if k == "start_values":
                    r["system"]["units"][0]["start_values"] = {"x": [1]}
                elif k == "report":
                    next(iter(r["fmus"].values()))["report"]["states"] = "many"
                else:
                    r["system"][k] = [None, 1, "x"]
                r["digest"] = ac._seal(key, r)
            else:  # reformat: the same content, other white space and key order
                changed = False
                rec.write_text(json.dumps(r, indent=rng.choice([None, 1, 4]), sort_keys=rng.random() < 0.5))
            if cls != "reformat":
                # an edit that wrote the value already there (inputs = [] over []) damaged nothing
                changed = r != json.loads(raw)
                rec.write_text(json.dumps(r))
        elif cls == "hostile-json":
            rec.write_text(rng.choice(["[]", "1", "null", '"x"', "[" * 100000 + "]" * 100000,
                                      '{"format": 3, "fmus": []}', '{"format": 3, "digest": 1}',
                                      json.dumps({"format": 3, "x": "y" * 100000}), "{" * 50000]))
        elif cls == "not-utf8":
            rec.write_bytes(raw[:50] + b"\xff\xfe\x00" + raw[50:])
        elif cls == "directory":
            rec.unlink()
            rec.mkdir()
        elif cls == "device":
            rec.unlink()
            rec.symlink_to("/dev/zero")
        elif cls == "big":
            with open(rec, "ab") as f:
                f.truncate(ac.MAX_RECORD_BYTES + 10)
        elif cls == "fmu-bytes":
            g = rng.choice(sorted(fmus))
            b = bytearray(fmus[g])
            b[rng.randrange(len(b))] ^= 0x20
            (folder / f"{g}.fmu").write_bytes(bytes(b))
        else:  # fmu-missing
            (folder / f"{rng.choice(sorted(fmus))}.fmu").unlink()
        out = self.dir / f"cache_out_{n}"
        self.what = cls

        def call():
            c = ac.cached_analysis(scene_path)
            if c is None:
                return None
            built = c.materialise(out)
            if built is None:
                return None
            return c, built

        def ok(result):
            if result is None:  # ignored: analysed and built again by the caller
                self.counts["cache"][cls][1] -= 1
                self.counts["cache"][cls][2] += 1
                return "a record this class did not damage was not served" if not changed else None
            c, built = result
            if changed:
                return "a damaged or edited record (or FMU) was served"
            if c.record != record:
                return "the record served is not the record written"
            for g, b in fmus.items():
                if (out / f"{g}.fmu").read_bytes() != b:
                    return f"the FMU {g}.fmu served is not the one written"
            return None

        self._check("cache", cls, n, None, call, accepted=ok)
        for p in self.dir.glob("evil*"):
            self._finding("cache", cls, n, f"a forged record wrote {p}")

    # -- running -------------------------------------------------------------------------------------------
    def run(self, cases: int, surfaces=("urdf", "component", "connect", "cache")) -> None:
        for n in range(cases):
            getattr(self, surfaces[n % len(surfaces)])(n)

    def table(self) -> str:
        rows = [f"{'surface':<10} {'class':<17} {'cases':>5} {'accepted':>8} {'refused':>7}"]
        for s in CLASSES:
            for cls in CLASSES[s]:
                c = self.counts[s].get(cls)
                if c:
                    rows.append(f"{s:<10} {cls:<17} {c[0]:>5} {c[1]:>8} {c[2]:>7}")
        total = sum(c[0] for s in self.counts.values() for c in s.values())
        rows.append(f"seed {self.seed}: {total} cases, {len(self.findings)} findings")
        return "\n".join(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=400)
    ap.add_argument("--seed", type=int, default=20261203)
    ap.add_argument("--surface", action="append", choices=sorted(CLASSES), help="only these (repeatable)")
    ap.add_argument("--verbose", action="store_true", help="print every case's outcome")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="fmugen_fuzz_readers_") as d:
        old = os.environ.get("FMUGEN_CACHE")
        os.environ["FMUGEN_CACHE"] = str(Path(d) / "cache")  # never the user's own cache
        try:
            r = Runner(args.seed, Path(d))
            r.verbose = args.verbose
            r.run(args.cases, tuple(args.surface or ("urdf", "component", "connect", "cache")))
        finally:
            if old is None:
                os.environ.pop("FMUGEN_CACHE", None)
            else:
                os.environ["FMUGEN_CACHE"] = old
        for f in r.findings:
            print("FINDING", f)
        print(r.table())
    return 1 if r.findings else 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))  # the checkout's fmugen, run from anywhere
    sys.exit(main())
