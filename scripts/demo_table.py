#!/usr/bin/env python3
"""Prints the demo's result table from the clouds scripts/demo.sh left in OUT.

For each object: the paper's numbers; ours with the calibrated sensor; ours with the true sensor
files (the same stripes, so the floor set by image noise alone). Two kinds of error are shown:
- fit σ: standard deviation of the distances to the best-fitting primitive (what the paper's
  "standard deviation" measures: noise about the shape); plus the fitted radius error;
- vs truth: mean signed error and σ of the distances to the scene's true surfaces. The calibrated
  sensor measures in its own frame; it is registered to the truth frame through the calibration
  rig (omni-eval align), as a metrology lab uses its reference artefact as the datum.
Usage: demo_table.py OUT OBJECT...
       demo_table.py --reducer OUT             (the plane's named speckle reducer: "PATTERNS F")
       demo_table.py --optics CAMERA PATTERNS F (CAMERA's file with those optics, to stdout)
       demo_table.py --reducer-measured OUT    (the plane scanned through it, against the prediction)
"""
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PAPER = {"plane": (0.21, 0.49), "cylinder": (0.24, 0.93), "sphere": (-0.17, 1.24)}
SHAPE = {"plane": ("plane", None), "cylinder": ("cylinder", 50.0), "sphere": ("sphere", 50.0)}
# The targets: σ fit at most half the paper's, radius errors within 0.1 mm.
TARGET_SIGMA = {obj: 0.5 * sigma for obj, (_, sigma) in PAPER.items()}
TARGET_RADIUS_MM = 0.1
# The lens apertures the budget is evaluated at when a target is missed.
F_STOPS = [1.4, 2.0, 2.8, 4.0, 5.6, 8.0, 11.0]
# Independent speckle patterns tried when no aperture meets a target (omni-eval budget's range).
SPECKLE_PATTERNS = [4, 8, 16]


def eval_json(*args):
    out = subprocess.run(["omni-eval", *args, "--json"], check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def measure(out, obj, cloud, transform):
    scene = os.path.join(HERE, "testdata", "scenes", obj + ".json")
    extra = ["--transform", transform] if transform else []
    compare = eval_json("compare", "--scene", scene, *extra, cloud)
    rows = []
    for o in compare["objects"]:
        fit_sigma, radius_err, radius_se = None, None, None
        kind = SHAPE.get(obj if len(compare["objects"]) == 1 else "", None)
        if kind:
            shape, radius = kind
            fit_args = ["fit", "--shape", shape, *extra] + (["--radius", str(radius)] if radius else [])
            fit = eval_json(*fit_args, cloud)
            fit_sigma = fit["errors"]["std_dev"]
            radius_err = fit.get("radius_error_mm")
            radius_se = fit.get("radius_error_se_mm")
        e = o["errors"]
        rows.append((o["name"], e["count"], e["mean"], e["std_dev"], fit_sigma, radius_err, radius_se))
    return rows


def budget(out, f_number=None, speckle_patterns=None):
    """The error budget's 500 mm line for the calibrated sensor (omni-eval budget), at the
    camera's own optics or at `f_number` / `speckle_patterns`; with the optics it assumed."""
    calib = os.path.join(out, "calib")
    extra = ["--f-number", str(f_number)] if f_number else []
    extra += ["--speckle-patterns", str(speckle_patterns)] if speckle_patterns else []
    doc = eval_json("budget", "--camera", os.path.join(calib, "camera.json"),
                    "--scanner", os.path.join(calib, "scanner.json"), "--range", "500", *extra)
    return {**doc["lines"][0], "f_number": doc["optics"]["f_number"],
            "speckle_patterns": doc["optics"]["speckle_patterns"]}


def targets(out, results, b):
    """Each object's σ fit and radius error against the targets. Where σ misses, the measured
    σ scaled by the budget's ratio at other apertures says which F-number would meet it."""
    print()
    print(f"targets: σ fit ≤ half the paper's, |radius error| ≤ {TARGET_RADIUS_MM} mm (calibrated sensor)")
    sweep = None
    for obj, target in TARGET_SIGMA.items():
        row = results.get(obj, {}).get("calibrated")
        if not row or row["sigma_fit_mm"] is None:
            continue
        sigma, rad = row["sigma_fit_mm"], row["radius_error_mm"]
        verdict = "met" if sigma <= target else "missed"
        line = f"  {obj:<9} σ fit {sigma:.3f} mm at F/{b['f_number']:g} (target {target:.3f}): {verdict}"
        if rad is not None:
            line += f"; radius {rad:+.3f} mm: {'met' if abs(rad) <= TARGET_RADIUS_MM else 'missed'}"
        print(line)
        if sigma <= target:
            continue
        if sweep is None:
            sweep = [(f, budget(out, f)) for f in F_STOPS]
        scaled = [(f, sigma * line["total_mm"] / b["total_mm"]) for f, line in sweep]
        print("            scaled by the budget: " + ", ".join(f"F/{f:g} {s:.3f}" for f, s in scaled))
        meeting = [f for f, s in scaled if s <= target]
        if meeting:
            print(f"            the target needs F/{max(meeting):g} or a wider aperture")
        else:
            widest = sweep[0][1]
            terms = {"speckle": widest["speckle_mm"], "noise": widest["noise_mm"],
                     "calibration": widest["calibration_mm"] or 0.0}
            print(f"            no aperture from F/{F_STOPS[0]:g} to F/{F_STOPS[-1]:g} meets it: "
                  f"{max(terms, key=terms.get)} sets the limit (budget {widest['total_mm']:.3f} mm per point "
                  f"at 500 mm even at F/{F_STOPS[0]:g})")
            reduced = speckle_reduction(out, sigma, b, target)
            if reduced:
                n, f, s = reduced
                print(f"            with a speckle reducer: {n} patterns (contrast {n ** -0.5:.2f} against "
                      f"{b['speckle_patterns'] ** -0.5:.2f}) at F/{f:g} or wider scale it to {s:.3f} mm")
                results[obj]["calibrated"]["speckle_reducer"] = {"patterns": n, "f_number": f, "sigma_fit_mm": s}
            else:
                print(f"            nor does a speckle reducer of up to {SPECKLE_PATTERNS[-1]} patterns")
        results[obj]["calibrated"]["f_number_sweep"] = dict((f"F/{f:g}", s) for f, s in scaled)


def speckle_reduction(out, sigma, b, target):
    """The fewest independent speckle patterns (a speckle reducer's averaging), and with them
    the largest F-number, whose budget scales the measured σ to the target:
    (patterns, F-number, scaled σ), or None."""
    for n in SPECKLE_PATTERNS:
        if n <= b["speckle_patterns"]:
            continue
        for f in sorted(F_STOPS, reverse=True):
            scaled = sigma * budget(out, f, n)["total_mm"] / b["total_mm"]
            if scaled <= target:
                return n, f, scaled
    return None


def fmt(x, width=8, signed=False):
    if x is None:
        return "-".rjust(width)
    return (f"{x:+.3f}" if signed else f"{x:.3f}").rjust(width)


def load_table(out):
    with open(os.path.join(out, "table.json")) as f:
        return json.load(f)


def save_table(out, table):
    """Writes OUT/table.json whole (a temporary file renamed into place)."""
    path = os.path.join(out, "table.json")
    with open(path + ".tmp", "w") as f:
        json.dump(table, f, indent=2)
    os.replace(path + ".tmp", path)


def reducer_named(table):
    """The plane's speckle reducer in the table: its entry (patterns, f_number, sigma_fit_mm) or None."""
    return table.get("plane", {}).get("calibrated", {}).get("speckle_reducer")


def with_optics(camera, patterns, f_number):
    """The camera file `camera` with its optics' speckle patterns and F-number replaced."""
    with open(camera) as f:
        doc = json.load(f)
    doc["optics"]["speckle_patterns"] = int(patterns)
    doc["optics"]["f_number"] = float(f_number)
    return doc


def reducer_measured(out):
    """Prints the plane's σ fit scanned through the named speckle reducer beside the budget's
    prediction, and adds it to OUT/table.json."""
    table = load_table(out)
    reducer = reducer_named(table)
    transform = os.path.join(out, "calib", "to_truth.json")
    rows = measure(out, "plane", os.path.join(out, "plane_reducer", "cloud.ply"), transform)
    sigma = rows[0][4]
    target = TARGET_SIGMA["plane"]
    print(f"  plane     through the speckle reducer ({reducer['patterns']} patterns, F/{reducer['f_number']:g}), "
          f"rendered: σ fit {sigma:.3f} mm (predicted {reducer['sigma_fit_mm']:.3f}, target {target:.3f}): "
          f"{'met' if sigma <= target else 'missed'}")
    reducer["rendered_sigma_fit_mm"] = sigma
    reducer["rendered_points"] = rows[0][1]
    save_table(out, table)


def main():
    if sys.argv[1:2] == ["--reducer"]:
        named = reducer_named(load_table(sys.argv[2]))
        if named:
            print(named["patterns"], named["f_number"])
        return
    if sys.argv[1:2] == ["--optics"]:
        json.dump(with_optics(*sys.argv[2:5]), sys.stdout, indent=2)
        return
    if sys.argv[1:2] == ["--reducer-measured"]:
        reducer_measured(sys.argv[2])
        return
    out, objects = sys.argv[1], sys.argv[2:]
    transform = os.path.join(out, "calib", "to_truth.json")
    results = {}
    b = budget(out)
    print("σ truth: spread of the points' signed distances to the scene's true surfaces; σ fit: spread")
    print("about the best-fitting primitive (the paper's measure); budget: the predicted σ per point at")
    print(f"500 mm (omni-eval budget): speckle {b['speckle_mm']:.3f}, noise {b['noise_mm']:.3f}, "
          f"calibration {fmt(b['calibration_mm'], 0).strip()}, total {b['total_mm']:.3f} mm")
    print()
    print(f"{'object':<21} {'sensor':<11} {'points':>7} {'mean':>8} {'σ truth':>8} {'σ fit':>8} {'budget':>8} {'radius':>8}   (mm)")
    for obj in objects:
        paper = PAPER.get(obj)
        if paper:
            print(f"{obj:<21} {'paper':<11} {'':>7} {fmt(paper[0], signed=True)} {'':>8} {fmt(paper[1])} {'':>8} {'-':>8}")
        for label, cloud, t in (
            ("calibrated", os.path.join(out, obj, "cloud.ply"), transform),
            ("true files", os.path.join(out, obj, "cloud_true_sensor.ply"), None),
        ):
            for name, n, mean, sd, fit_sd, rad, rad_se in measure(out, obj, cloud, t):
                tag = obj if name == obj else f"{obj}/{name}"
                print(f"{tag:<21} {label:<11} {n:>7} {fmt(mean, signed=True)} {fmt(sd)} {fmt(fit_sd)} "
                      f"{fmt(b['total_mm'])} {fmt(rad, signed=True)}")
                results.setdefault(tag, {})[label] = {
                    "points": n, "mean_mm": mean, "sigma_truth_mm": sd, "sigma_fit_mm": fit_sd, "radius_error_mm": rad,
                    "radius_error_se_mm": rad_se,
                }
    results["budget_500mm"] = b
    targets(out, results, b)
    save_table(out, results)


if __name__ == "__main__":
    main()
