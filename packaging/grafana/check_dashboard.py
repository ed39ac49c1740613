#!/usr/bin/env python3
"""Checks the Grafana dashboard: valid JSON, the fields Grafana's import needs, and every metric
an expression names is one the daemon exposes (the families in the daemon's sources).

usage: check_dashboard.py DASHBOARD.json SOURCE_DIR"""
import json
import pathlib
import re
import sys


def exposed_families(source_dir):
    names = set()
    for path in list(pathlib.Path(source_dir, "daemon").glob("*.cpp")) + list(
            pathlib.Path(source_dir, "src").rglob("*.cpp")):
        names.update(re.findall(r'family\(\s*"(ds1928_[a-z0-9_]+)"', path.read_text()))
    return names


def main():
    dashboard, source_dir = sys.argv[1], sys.argv[2]
    with open(dashboard, encoding="utf-8") as f:
        d = json.load(f)  # a syntax error stops here, with its line and column
    errors = []
    for key in ("uid", "title", "panels", "schemaVersion"):
        if key not in d:
            errors.append(f"missing top-level '{key}'")
    families = exposed_families(source_dir)
    if not families:
        errors.append(f"no metric families found under {source_dir}")
    ids = set()
    for p in d.get("panels", []):
        if p.get("id") in ids:
            errors.append(f"panel id {p.get('id')} used twice")
        ids.add(p.get("id"))
        targets = p.get("targets", [])
        if not targets:
            errors.append(f"panel '{p.get('title')}' has no query")
        for t in targets:
            for name in re.findall(r"\b(ds1928_[a-z0-9_]+)", t.get("expr", "")):
                base = re.sub(r"_(total|bucket|count|sum|info)$", "", name)
                if name not in families and base not in families:
                    errors.append(f"panel '{p.get('title')}': {name} is not a metric of ds1928d")
    for e in errors:
        print(f"{dashboard}: {e}", file=sys.stderr)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
