#!/usr/bin/env python3
# Mutation testing of flexbench's loaders: scenario YAML, declared-model YAML,
# calibration CSV (point and group formats), a closed_loop scenario (inline declared block, group
# distances), a MUKCa folder (../shared/data/mukca) and MJCF are
# mutated (byte flips, cuts, inserted tokens, duplicated or dropped lines, absurd numbers) and
# run through build/bin/flexbench (a copy, so rebuilding meanwhile is safe). Counts exit codes
# per loader; a problem is an exit code outside {0, 2, 3}, a bad-input exit without an error
# line, an output folder or temporary left behind, or MUJOCO_LOG.TXT. Writes
# <work>/result.json and keeps each problem's inputs in <work>/bad_N.
#   scripts/mutate_loaders.py [SEED] [SECONDS] [WORK_DIR]
import os, random, subprocess, sys, shutil, time, collections, json, tempfile
SRC = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
W = sys.argv[3] if len(sys.argv) > 3 else os.path.join(tempfile.gettempdir(), "flexbench_mutate")
shutil.rmtree(W, ignore_errors=True); os.makedirs(W)
F = os.path.join(W, "flexbench"); shutil.copy2(SRC + "/build/bin/flexbench", F)
rng = random.Random(int(sys.argv[1]) if len(sys.argv) > 1 else 21)
budget_s = float(sys.argv[2]) if len(sys.argv) > 2 else 900
TOKENS = [b"nan", b"inf", b"-1", b"0", b"1e308", b"1e200", b"-1e-300", b"\xe9", b"\xef\xbb\xbf",
          b"[", b"]", b"{", b"}", b":", b",", b"---\n", b"? [a, b]\n: 1\n", b"\x00", b"\n",
          b"&a", b"*a", b"!!binary", b"a" * 300, b"\"", b"'", b"#", b" - ", b"\t", b"..", b"/",
          b"<", b">", b"</body>", b"=\"-5\"", b"=\"60000\"", b"1e-300", b"99999999999999999999"]
def mutate(data):
    d = bytearray(data)
    for _ in range(rng.choice([1, 1, 1, 2, 3, 5])):
        op = rng.randrange(7)
        p = rng.randrange(len(d) + 1) if d else 0
        if op == 0 and d: d[min(p, len(d) - 1)] = rng.randrange(256)
        elif op == 1 and d: del d[p:p + rng.randrange(1, 20)]
        elif op == 2: d[p:p] = rng.choice(TOKENS)
        elif op == 3:
            lines = bytes(d).split(b"\n"); i = rng.randrange(len(lines)); lines.insert(i, lines[rng.randrange(len(lines))]); d = bytearray(b"\n".join(lines))
        elif op == 4:
            lines = bytes(d).split(b"\n"); i = rng.randrange(len(lines)); del lines[i]; d = bytearray(b"\n".join(lines))
        elif op == 5: d = d[:p]
        else:
            # replace a number-ish token
            s = bytes(d); digits = [i for i, c in enumerate(s) if 48 <= c <= 57]
            if digits: i = rng.choice(digits); d[i:i+1] = rng.choice([b"1e300", b"-", b"nan", b"9"*40, b"0.0", b"-5"])
    return bytes(d)

def read(p): return open(p, "rb").read()
planar_xml = read(SRC + "/models/planar3.xml")
smoke = read(SRC + "/scenarios/smoke.yaml").replace(b"../models/", (SRC + "/models/").encode())
decl = read(SRC + "/models/planar3.declared.yaml").replace(b"model: planar3.xml", ("model: " + SRC + "/models/planar3.xml").encode())
random.seed(3)
csv = b"joint1,joint2,joint3,x,y,z\n" + b"".join(b"%.4f,%.4f,%.4f,%.4f,%.4f,0.1\n" % (0.05*i, -0.03*i, 0.02*i, 0.3-0.01*i, 0.01*i) for i in range(25))
csvg = b"joint1,joint2,joint3,group,set\n" + b"".join(b"%.4f,%.4f,%.4f,g%d,s%d\n" % (0.05*i, -0.03*i, 0.02*i, i % 3, i % 2) for i in range(25))
MUKCA = os.path.normpath(SRC + "/../shared/data/mukca")
muk_src = MUKCA + "/data/panda_6/front"
muk_rows = {h: b"\n".join(read(f"{muk_src}/hole_{h}.csv").split(b"\n")[:12]) + b"\n" for h in (0, 1)} if os.path.isdir(muk_src) else {}
muk_yaml = read(SRC + "/scenarios/closed_loop_mukca_panda.yaml").replace(b"../../shared", os.path.normpath(SRC + "/../shared").encode())
def muk_scenario(d): 
    y = muk_yaml.replace((MUKCA + "/data/panda_6, placements: [front]").encode(), (d + ", placements: [front]").encode())
    y = y.replace((MUKCA + "/data/panda_6, placements: [left, right]").encode(), (d + ", placements: [front]").encode())
    return y.replace(b"candidates: [joint_offset, joint_axis_tilt, link_offset, link_length]", b"candidates: [joint_offset]")

def run(cmd, cwd):
    t = time.time()
    try:
        p = subprocess.run(cmd, cwd=cwd, stdin=subprocess.DEVNULL, capture_output=True, timeout=60)
        return p.returncode, p.stderr, time.time() - t
    except subprocess.TimeoutExpired:
        return "timeout", b"", 60
    except OSError as e:
        return "oserror", str(e).encode(), 0

hist = collections.defaultdict(collections.Counter); bad = []
start = time.time(); n = 0
# A closed_loop scenario on a group CSV with an inline declared block and group distances.
cl_yaml = (b"scenario: cl\nkind: closed_loop\nseed: 1\nmodel: " + (SRC + "/models/planar3.xml").encode() +
           b"\ndeclared:\n  model: " + (SRC + "/models/planar3.xml").encode() +
           b"\n  actuated_joints: [joint1, joint2, joint3]\n  end_effector: ee\n  sources:\n"
           b"    - {at: joint1, about_axis_deg: 1}\ncalibration: {csv: cal.csv, distances: [[g0, g1, 0.05]]}\n"
           b"validation: {csv: val.csv}\ncandidates: [joint_offset]\nmax_effects: 2\n")
loaders = ["scenario", "declared", "csv", "csv_group", "mjcf", "closed_loop"] + (["mukca"] if os.path.isdir(muk_src) else [])
while time.time() - start < budget_s:
    kind = loaders[n % len(loaders)]; n += 1
    case = os.path.join(W, "c"); shutil.rmtree(case, ignore_errors=True); os.makedirs(case)
    out = os.path.join(case, "out")
    if kind == "scenario":
        open(case + "/s.yaml", "wb").write(mutate(smoke)); cmd = [F, "run", "s.yaml", "--out", out, "--check-gates"]
    elif kind == "declared":
        open(case + "/d.declared.yaml", "wb").write(mutate(decl))
        open(case + "/cal.csv", "wb").write(csv); open(case + "/val.csv", "wb").write(csv + b"0.5,0.5,0.5,0.2,0.2,0.1\n")
        cmd = ([F, "inspect", "d.declared.yaml"] if n % 2 else
               [F, "identify", "--declared", "d.declared.yaml", "--calibration", "cal.csv", "--validation", "val.csv", "--out", out, "--candidates", "joint_offset"])
    elif kind in ("csv", "csv_group"):
        base = csv if kind == "csv" else csvg
        open(case + "/cal.csv", "wb").write(mutate(base)); open(case + "/val.csv", "wb").write(base + b"0.5,0.5,0.5,0.2,0.2,0.1\n" if kind == "csv" else base + b"0.5,0.5,0.5,g1,s0\n")
        cmd = [F, "identify", "--declared", SRC + "/models/planar3.declared.yaml", "--calibration", "cal.csv", "--validation", "val.csv", "--out", out, "--candidates", "joint_offset"]
    elif kind == "mukca":
        os.makedirs(case + "/m/front")
        h = rng.randrange(2)
        open(f"{case}/m/front/hole_{h}.csv", "wb").write(mutate(muk_rows[h])); open(f"{case}/m/front/hole_{1-h}.csv", "wb").write(muk_rows[1-h])
        y = muk_scenario(case + "/m")
        if rng.random() < 0.3: y = mutate(y)
        open(case + "/s.yaml", "wb").write(y); cmd = [F, "run", "s.yaml", "--out", out]
    elif kind == "closed_loop":
        open(case + "/s.yaml", "wb").write(mutate(cl_yaml)); open(case + "/cal.csv", "wb").write(csvg)
        open(case + "/val.csv", "wb").write(csv)
        cmd = [F, "run", "s.yaml", "--out", out]
    else:
        open(case + "/m.xml", "wb").write(mutate(planar_xml))
        open(case + "/s.yaml", "wb").write(smoke.replace((SRC + "/models/planar3.xml").encode(), b"m.xml"))
        cmd = [F, "inspect", "m.xml"] if n % 2 else [F, "run", "s.yaml", "--out", out]
    rc, err, dt = run(cmd, case)
    hist[kind][rc] += 1
    lines = err.decode("utf-8", "replace").rstrip("\n").split("\n") if err else []
    problem = None
    if rc not in (0, 2, 3): problem = "rc"
    elif rc == 2 and not (lines and (lines[-1].startswith("flexbench: error") or lines[-1].startswith("flexbench: simulation error") or lines[-1].startswith("[flexbench] ") is False)):
        problem = "no error line"
    elif rc == 2 and len(lines[-1]) > 1200: problem = "long line"
    elif rc == 2 and os.path.exists(out): problem = "output left after bad input"
    if os.path.exists(case + "/MUJOCO_LOG.TXT"): problem = "MUJOCO_LOG.TXT"
    if any(".tmp-" in f for f in os.listdir(case)): problem = "tmp left"
    if problem:
        keep = os.path.join(W, f"bad_{len(bad)}"); shutil.copytree(case, keep)
        bad.append({"kind": kind, "rc": rc, "problem": problem, "cmd": " ".join(cmd), "dir": keep, "err": lines[-3:] if lines else []})
summary = {"runs": n, "seconds": round(time.time() - start), "histogram": {k: {str(r): c for r, c in v.items()} for k, v in hist.items()}, "problems": len(bad)}
json.dump({"summary": summary, "bad": bad[:50]}, open(os.path.join(W, "result.json"), "w"), indent=1)
print(json.dumps(summary, indent=1))
