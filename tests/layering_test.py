#!/usr/bin/env python3
"""The layering of the tree (docs/ARCHITECTURE.md: data flows agent -> server -> viewer, and
model_store is the ground floor): no file under model_store/ or fusion_server/ includes a header of
a folder above it, and no target defined there links one defined above it, directly or through
others. Above means, for model_store/: sensor_agent/, fusion_server/, viewer_client/ and tests/
(test support such as tests/truth/ links the simulator); for fusion_server/: sensor_agent/,
viewer_client/ and tests/.

    layering_test.py SOURCE_DIR LINK_GRAPH   (LINK_GRAPH: <build>/ave_link_graph.tsv, written at
                                              configure time by ave_write_link_graph)

It first checks itself on a small made-up tree and graph that break each rule, so a checker that
has stopped finding anything fails too. Exit 0 when clean; otherwise one line per violation.
"""
import os
import re
import sys
import tempfile

FORBIDDEN = {
    "model_store": ("sensor_agent", "fusion_server", "viewer_client", "tests"),
    "fusion_server": ("sensor_agent", "viewer_client", "tests"),
}
SOURCE_ENDINGS = (".h", ".hh", ".hpp", ".c", ".cc", ".cpp", ".cxx", ".inc", ".ipp")
INCLUDE = re.compile(r'^\s*#\s*include\s*[<"]([^>"]+)[>"]')


def top_folder(rel_path):
    return rel_path.replace("\\", "/").split("/", 1)[0]


def include_violations(source_dir):
    """Includes (C++) and path references (CMake) from a lower folder into a higher one."""
    out = []
    for low, high in FORBIDDEN.items():
        for root, _, files in os.walk(os.path.join(source_dir, low)):
            for name in sorted(files):
                path = os.path.join(root, name)
                rel = os.path.relpath(path, source_dir)
                is_cmake = name == "CMakeLists.txt" or name.endswith(".cmake")
                if not (is_cmake or name.endswith(SOURCE_ENDINGS)):
                    continue
                with open(path, encoding="utf-8", errors="replace") as f:
                    for number, line in enumerate(f, 1):
                        if is_cmake:
                            code = line.split("#", 1)[0]
                            for folder in high:
                                if re.search(r"(^|[\s/\"(])" + folder + r"/", code):
                                    out.append(f"{rel}:{number}: refers to {folder}/ ({line.strip()})")
                            continue
                        m = INCLUDE.match(line)
                        if m and top_folder(m.group(1)) in high:
                            out.append(f"{rel}:{number}: includes {m.group(1)}")
    return out


def read_graph(path):
    """target -> (folder relative to the project, [link items], [sources])."""
    graph = {}
    with open(path, encoding="utf-8") as f:
        for line in f:
            fields = line.rstrip("\n").split("\t")
            if len(fields) < 2 or not fields[0]:
                continue
            links = [x for x in (fields[2].split(";") if len(fields) > 2 else []) if x]
            sources = [x for x in (fields[3].split(";") if len(fields) > 3 else []) if x]
            graph[fields[0]] = (fields[1], links, sources)
    return graph


def link_name(item):
    """A link item as a target name: $<LINK_ONLY:x> and similar wrappers removed."""
    while item.startswith("$<") and ":" in item and item.endswith(">"):
        item = item[item.index(":") + 1 : -1]
    return item


def link_violations(graph, source_dir):
    out = []
    for target, (folder, _, sources) in sorted(graph.items()):
        low = top_folder(folder)
        if low not in FORBIDDEN:
            continue
        high = FORBIDDEN[low]
        # Sources compiled in by path (the fuzz targets do this) count like includes.
        for src in sources:
            if src.startswith("$<"):
                continue
            full = os.path.normpath(src if os.path.isabs(src) else os.path.join(source_dir, folder, src))
            rel = os.path.relpath(full, source_dir)
            if not rel.startswith("..") and top_folder(rel) in high:
                out.append(f"target {target} ({folder}) compiles {rel}")
        # Breadth-first over the targets it links, remembering the path for the message.
        seen = {target: None}
        queue = [target]
        while queue:
            current = queue.pop(0)
            for item in graph[current][1]:
                dep = link_name(item)
                if dep not in graph or dep in seen:
                    continue
                seen[dep] = current
                dep_folder = graph[dep][0]
                if top_folder(dep_folder) in high:
                    chain = [dep]
                    while seen[chain[-1]] is not None:
                        chain.append(seen[chain[-1]])
                    out.append(f"target {target} ({folder}) links {dep} ({dep_folder}): "
                               + " -> ".join(reversed(chain)))
                    continue
                queue.append(dep)
    return out


def self_test():
    """Each rule must fire on a made-up tree that breaks it, and stay quiet on one that does not."""
    with tempfile.TemporaryDirectory() as root:
        def write(rel, text):
            path = os.path.join(root, rel)
            os.makedirs(os.path.dirname(path), exist_ok=True)
            with open(path, "w") as f:
                f.write(text)
        write("model_store/a/ok.cc", '#include "model_store/geometry/x.h"\n// sensor_agent/sim is fine in prose\n')
        write("model_store/a/bad.cc", '#include <vector>\n  #include "sensor_agent/sim/scenario.h"\n')
        write("fusion_server/b/bad.h", '#include "viewer_client/render/renderer.h"\n')
        write("fusion_server/fuzz/CMakeLists.txt", "# sensor_agent/ in a comment is fine\nadd_executable(f ../../sensor_agent/x.cc)\n")
        found = include_violations(root)
        expect = ["model_store/a/bad.cc:2", "fusion_server/b/bad.h:1", "fusion_server/fuzz/CMakeLists.txt:2"]
        for e in expect:
            if not any(v.startswith(e) for v in found):
                return [f"self-test: include check missed {e} (found {found})"]
        if len(found) != len(expect):
            return [f"self-test: include check flagged too much: {found}"]
        graph_path = os.path.join(root, "graph.tsv")
        write("graph.tsv", "\n".join([
            "ave_geometry\tmodel_store/geometry\t\tgeometry.cc",
            "ave_store\tmodel_store/db\tave_geometry;$<LINK_ONLY:ave_truth>\tstore.cc",
            "ave_truth\ttests/truth\tave_sim\ttruth.cc",
            "ave_sim\tsensor_agent/sim\tave_geometry\tsim.cc",
            "ave_server\tfusion_server/service\tave_store\tserver.cc",
            "ave_core\tfusion_server/core\tave_geometry\tcore.cc;../../sensor_agent/sim/sim.cc",
            "ave_bench\ttests/bench\tave_sim;ave_server\tbench.cc",
        ]) + "\n")
        found = link_violations(read_graph(graph_path), root)
        expect = ["target ave_store (model_store/db) links ave_truth",
                  "target ave_server (fusion_server/service) links ave_truth",
                  "target ave_core (fusion_server/core) compiles sensor_agent/sim/sim.cc"]
        for e in expect:
            if not any(v.startswith(e) for v in found):
                return [f"self-test: link check missed '{e}' (found {found})"]
        if len(found) != len(expect):
            return [f"self-test: link check flagged too much: {found}"]
    return []


def main():
    if len(sys.argv) != 3:
        print(__doc__)
        return 2
    source_dir, graph_path = sys.argv[1], sys.argv[2]
    problems = self_test()
    if not os.path.exists(graph_path):
        problems.append(f"{graph_path}: missing (re-run cmake: ave_write_link_graph writes it)")
        graph = {}
    else:
        graph = read_graph(graph_path)
        if not any(top_folder(folder) == "model_store" for folder, _, _ in graph.values()):
            problems.append(f"{graph_path}: holds no model_store target; is it this tree's graph?")
    problems += include_violations(source_dir) + link_violations(graph, source_dir)
    for p in problems:
        print(p)
    checked = sum(1 for folder, _, _ in graph.values() if top_folder(folder) in FORBIDDEN)
    print(f"layering: {len(problems)} problem(s); {checked} model_store/fusion_server targets checked")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
