#!/usr/bin/env python3
"""Builds the seed corpora in fuzz/corpus/<target>/ from tests/fixtures and animations/.

Run from the crate root: python3 fuzz/seed.py. GLB seeds pack each animation's .gltf,
.bin and small textures into one file (the gltf target reads no files beside its input);
the USD seeds prefix each file with its kind byte (fuzz_targets/usd.rs); the AFF seed joins the fixture scene, its include and its texture in the NUL-separated
layout of fuzz_targets/aff.rs; the OBJ seed is `mipray export` of the default animation.
"""
import json, os, pathlib, struct, subprocess, sys, tempfile

root = pathlib.Path(__file__).resolve().parent.parent
corpus = root / "fuzz" / "corpus"
hostile = root / "tests" / "fixtures" / "hostile"


def put(target, name, data):
    d = corpus / target
    d.mkdir(parents=True, exist_ok=True)
    (d / name).write_bytes(data)


def glb(gltf_path, max_image_bytes=40000):
    doc = json.loads(gltf_path.read_text())
    bin_ = bytearray((gltf_path.parent / doc["buffers"][0]["uri"]).read_bytes())
    del doc["buffers"][0]["uri"]
    for image in doc.get("images", []):
        data = (gltf_path.parent / image.pop("uri")).read_bytes()
        if len(data) > max_image_bytes:  # keep seeds small: a 1x1 stand-in
            data = (root / "animations" / "robots_pavement.png").read_bytes()
        while len(bin_) % 4:
            bin_.append(0)
        doc["bufferViews"].append({"buffer": 0, "byteOffset": len(bin_), "byteLength": len(data)})
        image["bufferView"] = len(doc["bufferViews"]) - 1
        image["mimeType"] = "image/png"
        bin_ += data
    while len(bin_) % 4:
        bin_.append(0)
    doc["buffers"][0]["byteLength"] = len(bin_)
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    total = 12 + 8 + len(js) + 8 + len(bin_)
    return (b"glTF" + struct.pack("<II", 2, total) + struct.pack("<I", len(js)) + b"JSON" + js
            + struct.pack("<I", len(bin_)) + b"BIN\0" + bytes(bin_))


fixtures = root / "tests" / "fixtures" / "aff"
scene, parts, checker = (fixtures / n for n in ["scene.aff", "parts.aff", "checker.ppm"])
put("aff", "fixture_scene", scene.read_bytes() + b"\0parts.aff\n" + parts.read_bytes()
    + b"\0checker.ppm\n" + checker.read_bytes())
put("aff", "fixture_parts", parts.read_bytes())
put("ppm", "checker.ppm", checker.read_bytes())
put("ppm", "p3.ppm", b"P3\n2 2\n255\n255 0 0 0 255 0 0 0 255 255 255 255\n")
put("ppm", "p6_16bit.ppm", b"P6\n1 1\n65535\n" + bytes(6))
for png in sorted((root / "animations").glob("*.png")):
    if png.stat().st_size < 4000:
        put("ppm", png.name, png.read_bytes())
for name in ["default", "kitchen", "robots"]:
    put("gltf", name + ".glb", glb(root / "animations" / (name + ".gltf")))

binary = os.environ.get("MIPRAY", str(root / "target" / "release" / "mipray"))
with tempfile.TemporaryDirectory() as tmp:
    subprocess.run([binary, "export", "default", "--frames", "0", "--format", "obj", "--out", tmp],
                   cwd=root, check=True, stdout=subprocess.DEVNULL)
    for f in sorted(pathlib.Path(tmp).glob("*.obj")):
        put("obj", f.name, f.read_bytes())

# USD: the first byte picks the kind (0 text, 1 crate, 2 package), as fuzz_targets/usd.rs
# reads it; the hostile corpus and a valid crate file written by openusd's writer (the
# ignored test in tests/usd_hostile.rs writes the damaged ones from the same file).
usd_kind = {".usda": b"\0", ".usdc": b"\1", ".usdz": b"\2"}
put("usd", "triangle.usda", b"\0" + b"""#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
    startTimeCode = 0
    endTimeCode = 2
)
def Xform "A"
{
    double3 xformOp:translate.timeSamples = { 0: (0, 0, 0), 2: (1, 0, 0) }
    uniform token[] xformOpOrder = ["xformOp:translate"]
    def Mesh "Tri"
    {
        uniform token subdivisionScheme = "none"
        int[] faceVertexCounts = [3]
        int[] faceVertexIndices = [0, 1, 2]
        point3f[] points.timeSamples = { 0: [(0, 0, 0), (1, 0, 0), (0, 1, 0)], 2: [(0, 0, 0), (1, 0, 1), (0, 1, 0)] }
        texCoord2f[] primvars:st = [(0, 0), (1, 0), (0, 1)] (interpolation = "faceVarying")
    }
}
""")
for f in sorted(hostile.glob("usd_*")) if hostile.is_dir() else []:
    if f.suffix in usd_kind:
        put("usd", "hostile_" + f.name, usd_kind[f.suffix] + f.read_bytes())

# The hostile corpus seeds each target with its own kind of file.
kinds = {".aff": "aff", ".ppm": "ppm", ".gltf": "gltf", ".glb": "gltf", ".obj": "obj"}
for f in sorted(hostile.glob("*")) if hostile.is_dir() else []:
    if f.suffix in kinds:
        put(kinds[f.suffix], "hostile_" + f.name, f.read_bytes())
print("seeded", {t.name: len(list(t.iterdir())) for t in corpus.iterdir()})
