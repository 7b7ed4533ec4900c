"""Imports a `mipray export` frame into Blender as the guide (docs/src/export.md) says and prints what came in.

Run by tests/blender_import.rs:

    blender -b --factory-startup --python-exit-code 1 --python tests/blender/check_import.py \
        -- EXPORT_DIR FRAME docs/src/export.md

Imports `frame_NNNN.obj` with File > Import > Wavefront (.obj) (the `wm.obj_import`
operator; the add-on listed as "(legacy)" does not read `Tf`) and the guide's axes, then
runs the guide's camera script itself (the Python block under "Importing a frame into
Blender", with its JSON path pointed at `camera_NNNN.json`), so the test checks the guide's
instructions, not a copy of them. Prints one line, `MIPRAY_BLENDER_CHECK <json>`, with the
face count, the materials on the imported objects (Principled BSDF inputs and base-colour
image), the loaded images, every imported vertex (world position and camera-view
coordinates) and the scene camera. The Rust test compares them with the exported files.
"""

import json
import re
import sys

import bpy
from bpy_extras.object_utils import world_to_camera_view

GUIDE_HEADING = "## Importing a frame into Blender"


def arguments():
    args = sys.argv[sys.argv.index("--") + 1:]
    if len(args) != 3:
        raise SystemExit("usage: ... -- EXPORT_DIR FRAME docs/src/export.md")
    return args[0], int(args[1]), args[2]


def guide_camera_script(guide_path, camera_json_path):
    """The guide's camera script with its camera_NNNN.json path replaced."""
    text = open(guide_path, encoding="utf-8").read()
    start = text.find(GUIDE_HEADING)
    if start < 0:
        raise SystemExit(f"{guide_path}: no '{GUIDE_HEADING}' section")
    block = re.search(r"```python\n(.*?)```", text[start:], re.S)
    if block is None:
        raise SystemExit(f"{guide_path}: no python block in '{GUIDE_HEADING}'")
    code, count = re.subn(r'open\("[^"]*camera_\d+\.json"\)',
                          lambda _: f"open({camera_json_path!r})", block.group(1))
    if count != 1:
        raise SystemExit(f"{guide_path}: the camera script should open one camera_NNNN.json, found {count}")
    return code


def socket(bsdf, *names):
    """A Principled BSDF input's value; Blender 4 renamed some inputs (e.g. 'Transmission Weight')."""
    for name in names:
        if name in bsdf.inputs:
            return bsdf.inputs[name].default_value
    raise KeyError(names)


def base_color_image(bsdf):
    links = bsdf.inputs["Base Color"].links
    if not links or links[0].from_node.type != "TEX_IMAGE" or links[0].from_node.image is None:
        return None
    return links[0].from_node.image


def material_record(material):
    bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    image = base_color_image(bsdf)
    return {
        "name": material.name,
        "transmission": socket(bsdf, "Transmission", "Transmission Weight"),
        "ior": socket(bsdf, "IOR"),
        "alpha": socket(bsdf, "Alpha"),
        "metallic": socket(bsdf, "Metallic"),
        "roughness": socket(bsdf, "Roughness"),
        "image": None if image is None else bpy.path.abspath(image.filepath),
    }


def main():
    export_dir, frame, readme = arguments()
    obj_path = f"{export_dir}/frame_{frame:04}.obj"
    camera_path = f"{export_dir}/camera_{frame:04}.json"

    bpy.ops.wm.read_factory_settings(use_empty=True)  # no default cube, camera or light
    # The guide's axes: Forward -Z, Up Y (mipray's, turned into Blender's +Z up).
    bpy.ops.wm.obj_import(filepath=obj_path, forward_axis="NEGATIVE_Z", up_axis="Y")
    exec(guide_camera_script(readme, camera_path), {})

    scene = bpy.context.scene
    camera = scene.camera
    meshes = [o for o in scene.objects if o.type == "MESH"]
    materials = {m.name: m for o in meshes for m in o.data.materials if m is not None}
    vertices = []
    for o in meshes:
        for v in o.data.vertices:
            world = o.matrix_world @ v.co
            view = world_to_camera_view(scene, camera, world)
            vertices.append([*world, *view])
    images = [i for i in bpy.data.images if i.source == "FILE"]
    record = {
        "blender_version": list(bpy.app.version),
        "objects": len(meshes),
        "faces": sum(len(o.data.polygons) for o in meshes),
        "materials": [material_record(m) for m in materials.values()],
        "images": [{"path": bpy.path.abspath(i.filepath), "size": list(i.size)} for i in images],
        "vertices": vertices,
        "camera": {
            "location": list(camera.matrix_world.translation),
            "rotation": [list(row) for row in camera.matrix_world.to_3x3()],
            "angle_y": camera.data.angle_y,
            "sensor_fit": camera.data.sensor_fit,
            "resolution": [scene.render.resolution_x, scene.render.resolution_y],
        },
    }
    print("MIPRAY_BLENDER_CHECK " + json.dumps(record))


main()
