#!/usr/bin/env python3
"""The deploy files (systemd units, compose file, Kubernetes manifests, scaling guide) start our
programs with flags; a renamed or mistyped flag would only show when someone deploys. Every
`ave-<program> [subcommand] --flag` written in them must be a flag that program (or subcommand)
lists in its --help. And no bearer token in clear (issue 14): an `ave-server --listen` on a
non-loopback address carries --tls-cert (or says --insecure-plaintext), and a client given --server
has a TLS CA (--tls-ca or AVE_TLS_CA in the same file) or says --insecure-plaintext.
Usage: deploy_files_test.py REPO BIN_DIR"""
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

def is_loopback(address):
    address = address.strip('"\'')
    if address.startswith("unix:"):
        return True
    host = address[1:address.find("]")] if address.startswith("[") else address.rsplit(":", 1)[0]
    return host in ("localhost", "::1") or host.startswith("127.")


failures, checked, transport_checked = [], 0, 0
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
        where = f"{path.relative_to(repo)}: ave-{program}"
        listen = re.search(r"--listen[\s,=]+\"?([^\s\",\]]+)", segment)
        if program == "server" and listen:
            transport_checked += 1
            if not is_loopback(listen.group(1)) and "--tls-cert" not in flags and "--insecure-plaintext" not in flags:
                failures.append(f"{where} listens on {listen.group(1)} in plaintext (no --tls-cert, no --insecure-plaintext)")
        if program in ("agent", "viewer", "admin") and "--server" in flags and path.suffix != ".md":  # not prose
            transport_checked += 1
            if "--tls-ca" not in flags and "AVE_TLS_CA" not in text and "--insecure-plaintext" not in flags:
                failures.append(f"{where} sends its token to --server in plaintext (no --tls-ca / AVE_TLS_CA)")
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
print(f"deploy files: {checked} flags checked in {len(files)} files, {transport_checked} transports checked, "
      f"{len(failures)} failures")
if checked < 10 or transport_checked < 4:
    print("FAIL: too few flags found; the extractor is broken")
    sys.exit(1)
sys.exit(1 if failures else 0)
