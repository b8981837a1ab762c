"""What a finished prediction run reports: summary.json's counts, timings and throughput, and the
lines the command prints from it."""

from __future__ import annotations

from pathlib import Path

from csboundary.data.footprint import union_area
from csboundary.data.model_view import mosaic_units
from csboundary.data.raster import Mosaic
from csboundary.data.units import GroundUnits
from csboundary.pipeline.prediction.city_job import CPU, STAGES, CityResult

SUMMARY = "summary.json"  # written last: it existing means the run finished
PIXEL_UNITS = GroundUnits((1.0, 1.0), "pixel")  # no CRS and no stated pixel size: lengths in pixels


def summarize(
    mosaic: Mosaic,
    result: CityResult,
    seconds: dict,
    files: dict,
    settings: dict,
    units: GroundUnits | None = None,
    counts: dict | None = None,
) -> dict:
    """Counts, timings and throughput of one run (JSON-ready); areas and lengths in true metres.
    ``counts`` are the writer's (:class:`~csboundary.pipeline.outputs.prediction_files.GraphWriter`); without
    them they are taken from ``result.graph``."""
    units = units or mosaic_units(mosaic) or PIXEL_UNITS
    if counts is None:
        counts = graph_counts(result.graph, units)
    area_km2 = (
        units.area_km2(mosaic.bounds) * union_area(mosaic.footprint) / mosaic.window.area
    )  # the imagery's, not its bounding box's
    n = result.n_patches
    kinds = counts["kinds"]
    return {
        "inputs": [
            str(Path(t.path).resolve()) for t in mosaic.tiles
        ],  # absolute: review and apply-review run from anywhere
        "crs": mosaic.crs.to_string() if mosaic.crs is not None else None,
        "length_unit": f"metre (from {units.unit_name}{', geodesic' if units.geographic else ''})",
        "mosaic_px": [mosaic.width, mosaic.height],
        "area_km2": round(area_km2, 6),
        "patches": n,
        "patches_without_imagery": result.patches_without_imagery,
        "grid": list(result.grid.shape),
        "counts": {
            "vertices": counts["vertices"],
            "edges": counts["edges"],
            "corner_edges": kinds.get("corner", 0),
            "skeleton_edges": kinds.get("skeleton", 0),  # filled in from the segmentation (graph/skeleton_fill.py)
            "attach_edges": kinds.get("attach", 0),  # a dangling end joined to the line ahead (graph/end_attachment.py)
            "boundaries": counts["boundaries"],
            "boundary_km": round(counts["boundary_m"] / 1000, 4),
            "patch_graph_edges": result.patch_graph_edges,
            "vertex_pairs_within_1px": result.close_vertex_pairs,
        },
        "seconds": {k: round(v, 3) for k, v in seconds.items() if not k.startswith(CPU)},
        "seconds_per_patch": {k: round(seconds[k] / n, 4) for k in (*STAGES, "total")},
        # the core seconds of the thread that ran each stage (the whole stage with one thread each)
        "core_seconds_per_patch": {k: round(seconds.get(CPU + k, 0.0) / n, 4) for k in STAGES},
        "km2_per_hour": round(area_km2 / (seconds["total"] / 3600), 3) if seconds["total"] > 0 else None,
        "map_store_peak_mb": round(result.map_bytes_peak / 2**20, 1),
        "work": result.work,
        "settings": settings,
        "files": {k: Path(v).name for k, v in files.items()},
    }


def graph_counts(graph, units: GroundUnits) -> dict:
    """What :class:`~csboundary.pipeline.outputs.prediction_files.GraphWriter` counts, of a whole graph."""
    from csboundary.pipeline.outputs.prediction_files import graph_frames

    kinds: dict[str, int] = {}
    for kind in graph.edge_kinds or ["normal"] * graph.n_edges:
        kinds[kind] = kinds.get(kind, 0) + 1
    boundaries, edges = graph_frames(graph, units)
    return {
        "vertices": graph.n_vertices,
        "edges": graph.n_edges,
        "kinds": kinds,
        "boundaries": len(boundaries),
        "boundary_m": float(edges["length_m"].sum()),
    }


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and the noun, plural unless one: "1 patch", "4 patches", "2 vertices"."""
    return f"{n} {noun}" if n == 1 else f"{n} {plural or noun + ('es' if noun.endswith(('ch', 'sh', 's')) else 's')}"


def written_files(folder: Path) -> str:
    """The finished files of an output folder, by name (what a run wrote, for the user)."""
    return ", ".join(
        sorted(p.name + ("/" if p.is_dir() else "") for p in Path(folder).iterdir() if not p.name.startswith("."))
    )


def stage_table(summary: dict) -> str:
    """Seconds per patch for each stage, one line."""
    per = summary["seconds_per_patch"]
    parts = ", ".join(f"{k.replace('_', ' ')} {per[k]:.3f}" for k in STAGES)
    return (
        f"{counted(summary['patches'], 'patch')}, {summary['area_km2']:.3f} km2 in {summary['seconds']['total']:.1f} s "
        f"({summary['km2_per_hour']} km2/h); s/patch: {parts}"
    )


def peak_rss_mb() -> float:
    """This process's peak resident memory so far, in MB (Linux reports kB)."""
    import resource

    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)
