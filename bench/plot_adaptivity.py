"""Plot the curves of ``bench/adaptivity.py`` (its markdown output) as an SVG: for each pair, polygons (log scale)
against Hausdorff p95 (voxels), Grid to Mesh's five points and AASDF's curve. No plotting library: the SVG is
written by hand.

    .venv/bin/python bench/plot_adaptivity.py adaptivity-output.md docs/images/adaptivity.svg
"""

from __future__ import annotations

import math
import re
import sys
from pathlib import Path

W, H, PAD = 300, 220, 44  # one panel
EXTRA = re.compile(r"([\d.]+): ([\d,]+) \(([\d.]+)\)")


def parse(text: str) -> dict:
    """{pair: {"gn": {adaptivity: (polygons, p95)}, "ours": {...}}} from the curves table (a row printed twice
    counts once)."""
    pairs: dict = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 8 or not cells[0] or cells[0] in ("pair", "---"):
            continue
        name = cells[0]
        entry = pairs.setdefault(name, {"gn": {}, "ours": {}})
        if cells[2] == "":  # the row of AASDF's other points
            for a, faces, p95 in EXTRA.findall(cells[1]):
                entry["ours"][float(a)] = (int(faces.replace(",", "")), float(p95))
            continue
        try:
            a = float(cells[1])
        except ValueError:
            continue
        entry["gn"][a] = (int(cells[2].replace(",", "")), float(cells[3].split("/")[0]))
        entry["ours"][a] = (int(cells[4].replace(",", "")), float(cells[6].split("/")[0]))
    return pairs


def panel(name: str, entry: dict, x0: float, y0: float) -> list[str]:
    points = list(entry["gn"].values()) + list(entry["ours"].values())
    lo, hi = math.log10(min(p[0] for p in points)) - 0.05, math.log10(max(p[0] for p in points)) + 0.05
    top = max(p[1] for p in points) * 1.1

    def xy(faces, p95):
        x = x0 + PAD + (math.log10(faces) - lo) / (hi - lo) * (W - PAD - 10)
        y = y0 + H - PAD + 10 - p95 / top * (H - PAD - 10)
        return x, y

    out = [f'<text x="{x0 + W / 2:.0f}" y="{y0 + 14:.0f}" text-anchor="middle" font-size="12">{name}</text>']
    out.append(
        f'<rect x="{x0 + PAD}" y="{y0 + 20}" width="{W - PAD - 10}" height="{H - PAD - 10}" fill="none" stroke="#999"/>'
    )
    for k in range(int(math.ceil(lo)), int(math.floor(hi)) + 1):
        x, y = xy(10**k, 0.0)
        out.append(f'<text x="{x:.0f}" y="{y + 14:.0f}" text-anchor="middle" font-size="9">1e{k}</text>')
    out.append(f'<text x="{x0 + PAD - 4}" y="{y0 + 28}" text-anchor="end" font-size="9">{top:.2f}</text>')
    out.append(f'<text x="{x0 + PAD - 4}" y="{y0 + H - PAD + 10}" text-anchor="end" font-size="9">0</text>')
    for series, colour in ((sorted(entry["gn"].values()), "#d62728"), (sorted(entry["ours"].values()), "#1f77b4")):
        path = " ".join(f"{x:.1f},{y:.1f}" for x, y in (xy(*p) for p in series))
        out.append(f'<polyline points="{path}" fill="none" stroke="{colour}" stroke-width="1.5"/>')
        out += [f'<circle cx="{x:.1f}" cy="{y:.1f}" r="2.5" fill="{colour}"/>' for x, y in (xy(*p) for p in series)]
    return out


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    pairs = parse(Path(argv[0]).read_text(encoding="utf-8"))
    cols = 3
    rows = math.ceil(len(pairs) / cols)
    width, height = cols * W, rows * H + 40
    body = []
    for k, (name, entry) in enumerate(pairs.items()):
        body += panel(name, entry, (k % cols) * W, (k // cols) * H)
    legend = (
        f'<text x="10" y="{height - 14}" font-size="11"><tspan fill="#d62728">Grid to Mesh, adaptivity 0-1</tspan>'
        f'  <tspan fill="#1f77b4">AASDF, adaptivity 0-1</tspan>  x: polygons (log), y: Hausdorff p95 to the exact '
        "boolean (voxels); lower left is better</text>"
    )
    svg = (
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" font-family="sans-serif">'
        f'<rect width="100%" height="100%" fill="white"/>{"".join(body)}{legend}</svg>\n'
    )
    Path(argv[1]).write_text(svg, encoding="utf-8")


if __name__ == "__main__":
    main()
