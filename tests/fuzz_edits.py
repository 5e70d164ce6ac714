"""Edits that make hostile CSV tables and URDFs (tests/fuzz_surfaces.py): duplicated headers, a
latin-1 byte, values of 1e308, Python-only number spellings (``0_5``), 20 000 columns, three rows,
bit flips, truncation, an over-long field or row; duplicated joints and links, origins and axes of
1e308 / NaN, nesting 100 000 deep, entity expansion, swapped limits, a non-UTF-8 name."""

from __future__ import annotations

import numpy as np

ARM = """<robot name="two">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.3" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.4 0 0" rpy="1.5707963 0 0"/><axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="fixed_tip" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="0.2 0 0"/></joint>
</robot>
"""
TOKENS = ["0_5", "1e308", "-1e308", "nan", "", "inf", "0x10", " 1 ", "\u0661\u0662", "1e-400", "--1", "1,5", '"',
          "1" * 400, "\x00", "true"]


# ----- edits of text and bytes -------------------------------------------------------------------
def flips(b: bytes, rng: np.random.Generator, n: int) -> bytes:
    out = bytearray(b)
    for p in rng.integers(0, len(out), n):
        out[p] ^= 1 << int(rng.integers(8))
    return bytes(out)


def _table(rng: np.random.Generator, rows: int = 12) -> list[list[str]]:
    v = np.column_stack([rng.uniform(-0.5, 0.5, (rows, 3)), rng.uniform(-1.5, 1.5, (rows, 2))])
    return [["x", "y", "z", "j2", "j1"]] + [[repr(float(x)) for x in r] for r in v]


def csv_bytes(rows: list[list[str]]) -> bytes:
    return ("\n".join(",".join(r) for r in rows) + "\n").encode()


def csv_edit(k: int, rng: np.random.Generator) -> bytes:
    t = _table(rng)
    i, j = int(rng.integers(1, len(t))), int(rng.integers(0, 5))
    how = k % 12
    if how == 0:
        t[0][int(rng.integers(1, 5))] = t[0][0]  # a duplicated header
    elif how == 1:
        b = csv_bytes(t)
        p = int(rng.integers(0, len(b)))
        return b[:p] + b"\xe9" + b[p:]  # one latin-1 byte
    elif how == 2:
        t[i][j] = ("1e308", "-1e308", "1e7")[k % 3]
    elif how == 3:
        t[i][j] = "0_5"
    elif how == 4:
        t[i][j] = TOKENS[int(rng.integers(len(TOKENS)))]
    elif how == 5:  # wide: 20 000 columns
        t = [r + ([f"c{c}" for c in range(20_000)] if n == 0 else ["1.5"] * 20_000) for n, r in enumerate(t)]
    elif how == 6:
        t = t[:4]  # three rows
    elif how == 7:
        return flips(csv_bytes(t), rng, int(rng.integers(1, 9)))
    elif how == 8:
        b = csv_bytes(t)
        return b[: int(rng.integers(0, len(b)))]
    elif how == 9:
        return b"\xef\xbb\xbf" + csv_bytes(t).replace(b"\n", b"\r\n")  # BOM and CRLF: fine
    elif how == 10:
        t[i][j] = "x" * 200_000  # a field over the limit
    else:
        t[i].append("7")  # a row longer than the header
    return csv_bytes(t)


def urdf_edit(k: int, rng: np.random.Generator) -> bytes:
    t = ARM
    how = k % 11
    if how == 0:
        t = t.replace('<joint name="j2"', '<joint name="j1"')
    elif how == 1:
        t = t.replace('<link name="l2"/>', '<link name="l2"/><link name="l1"/>')
    elif how == 2:
        t = t.replace('xyz="0.4 0 0"', f'xyz="{("1e308", "-1e308", "nan", "inf", "1e7")[k % 5]} 0 0"')
    elif how == 3:
        t = t.replace('rpy="1.5707963 0 0"', 'rpy="1.5707963 1e308 0"')
    elif how == 4:
        t = t.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 1e308"/>', 1)
    elif how == 5:
        return flips(t.encode(), rng, int(rng.integers(1, 9)))
    elif how == 6:
        return t.encode()[: int(rng.integers(0, len(t)))]
    elif how == 7:
        return b"<robot name=\"deep\">" + b"<a>" * 100_000 + b"</a>" * 100_000 + b"</robot>"
    elif how == 8:  # entity expansion ("billion laughs")
        ents = '<!ENTITY a0 "lol">' + "".join(f'<!ENTITY a{n} "{("&a" + str(n - 1) + ";") * 10}">' for n in range(1, 10))
        return f'<?xml version="1.0"?><!DOCTYPE robot [{ents}]><robot name="&a9;"/>'.encode()
    elif how == 9:
        t = t.replace('lower="-3" upper="3"', 'lower="3" upper="-3"')
    else:
        return t.encode().replace(b"two", b"tw\xe9")
    return t.encode()


