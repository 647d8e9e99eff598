#!/usr/bin/env python3
"""The deploy files (systemd units, compose file, Kubernetes manifests, scaling guide) start our
programs with flags; a renamed or mistyped flag would only show when someone deploys. Every
`ave-<program> [subcommand] --flag` written in them must be a flag that program (or subcommand)
lists in its --help. Usage: deploy_files_test.py REPO BIN_DIR"""
import pathlib
import re
import subprocess
import sys

repo, bin_dir = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
programs = "server|agent|viewer|admin|loadgen|sim|bench"
files = sorted((repo / "deploy").glob("systemd/*")) + sorted((repo / "deploy").glob("compose/*")) + \
    sorted((repo / "deploy").glob("k8s/*")) + [repo / "deploy" / "SCALING.md"]
mention = re.compile(r"\bave-(" + programs + r")\b(?![-.@])")
# A statement ends at a blank line, a new YAML key, or the next program mention.
end = re.compile(r"\n\s*\n|\n\s*[A-Za-z_]+:\s|\n\s*-\s+name:|\n\s*#")
help_cache = {}

def help_text(program, sub):
    key = (program, sub)
    if key not in help_cache:
        cmd = [str(bin_dir / f"ave-{program}")] + ([sub] if sub else []) + ["--help"]
        run = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
        help_cache[key] = (run.returncode, run.stdout + run.stderr)
    return help_cache[key]

failures, checked = [], 0
for path in files:
    if not path.is_file():
        continue
    text = path.read_text().replace("\\\n", " ")  # systemd / shell line continuations
    spans = list(mention.finditer(text))
    for i, m in enumerate(spans):
        stop = spans[i + 1].start() if i + 1 < len(spans) else len(text)
        e = end.search(text, m.end(), stop)
        segment = text[m.end(): e.start() if e else stop]
        program = m.group(1)
        words = re.findall(r"[A-Za-z0-9_.:/#@${}-]+", segment)
        sub = words[0] if words and re.fullmatch(r"[a-z][a-z-]+", words[0]) and not words[0].startswith("-") else None
        flags = sorted(set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", segment)))
        if not flags:
            continue
        rc, help_out = help_text(program, sub)
        if rc != 0 and sub:  # the word was not a subcommand after all
            sub = None
            rc, help_out = help_text(program, None)
        if rc != 0:
            failures.append(f"{path.name}: ave-{program} {sub or ''} --help exited {rc}")
            continue
        for flag in flags:
            checked += 1
            if not re.search(re.escape(flag) + r"\b", help_out):
                failures.append(f"{path.relative_to(repo)}: ave-{program}{' ' + sub if sub else ''} has no flag {flag}")

for f in failures:
    print("FAIL", f)
print(f"deploy files: {checked} flags checked in {len(files)} files, {len(failures)} unknown")
if checked < 10:
    print("FAIL: too few flags found; the extractor is broken")
    sys.exit(1)
sys.exit(1 if failures else 0)
