"""The room's materials and lights (issue 16 item 6, mode `room`, PSDR-Room section 4.4): crop
pairs, homogeneous albedos from shading-corrected median colours, procedural retrieval with the
transform search, then Eq. 4's joint optimisation of materials (through the adjoint) and light
radiances (exact per-light NNLS), as results/{scene}/room_materials/ (materials.json, lights.json,
thumbnails.png, room_materials.png; docs/room-materials.md). Its input functions are here, not in
common.smk: room_objects is taken when its rule is part of the workflow, as bake_room does.
"""


def room_materials_inputs(wildcards):
    results = f"results/{wildcards.scene}"
    inputs = {
        "capture": room_box_input(wildcards),
        "room": f"{results}/room_box",
        "lights": f"{results}/room_lights",
    }
    if "room_objects" in {rule.name for rule in workflow.rules}:
        inputs["objects"] = f"{results}/room_objects"
    return inputs


def room_materials_options(wildcards):
    """--objects when room_objects exists, the capture's named files, the config's settings,
    and the scene's user crop pairs (as JSON text)."""
    results = f"results/{wildcards.scene}"
    settings = config.get("room_materials", {})
    options = [room_lights_options(wildcards)]
    if "room_objects" in {rule.name for rule in workflow.rules}:
        options.append(f"--objects {results}/room_objects")
    options += [
        f"--rounds {settings.get('rounds', 4)}",
        f"--steps {settings.get('steps', 8)}",
        f"--spp {settings.get('spp', 8)}",
        f"--light-colour {settings.get('light_colour', 'grey')}",
        f"--eval-width {settings.get('eval_width', 256)}",
    ]
    if not settings.get("retrieval", True):
        options.append("--no-retrieval")
    crops = SCENES[wildcards.scene].get("room_materials", {}).get("crops", [])
    if crops:
        options.append(f"--crops {shlex.quote(json.dumps(crops))}")
    return " ".join(option for option in options if option)


rule room_materials:
    """The materials of the room's parts and the radiances of its lights, fitted to the photo."""
    input:
        unpack(room_materials_inputs),
    output:
        directory("results/{scene}/room_materials"),
    log:
        "results/{scene}/logs/room_materials.log",
    benchmark:
        "results/{scene}/benchmarks/room_materials.tsv"
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=3000,
        runtime=30,
        gpu=gpu_request,
    params:
        capture=capture_dir,
        options=room_materials_options,
        device=device_option,
    shell:
        "invrender --log {log} room-materials {params.capture:q} --room {input.room:q}"
        " --lights {input.lights:q} --out {output} {params.options} {params.device}"
