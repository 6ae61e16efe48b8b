"""The segment checkpoint (duplicates scenes): the copies of the object in the
photograph, as results/{scene}/segmentation/ (masks/<image stem>.png, instances.json,
overlay.png). A checkpoint: how many instances there are, and so the per-instance jobs
downstream, is known only once it has run (segmented_instances below).

Its settings, per scene, are `scenes.<name>.segment` in workflow/schemas/config.schema.yaml.
"""


def segment_settings(wildcards):
    return SCENES[wildcards.scene].get("segment", {})


def segment_backend(wildcards):
    return segment_settings(wildcards).get("backend", "opencv")


def segment_image(wildcards):
    """The photograph: a synthetic capture's one view (the generator names it view_000.exr),
    or the user's (`capture.image`, else the one image in images/)."""
    if is_synthetic(wildcards.scene):
        return os.path.join(capture_dir(wildcards), "images", "view_000.exr")
    return str(photograph(wildcards.scene))


def segment_masks(wildcards):
    """The provided backend's masks (None for opencv): `capture.masks`, or a synthetic
    capture's true id image (the generator names it as its view)."""
    if segment_backend(wildcards) != "provided":
        return None
    if is_synthetic(wildcards.scene):
        return os.path.join(
            capture_dir(wildcards), "ground_truth", "masks", "view_000.png"
        )
    capture = SCENES[wildcards.scene]["capture"]
    if "masks" not in capture:
        raise WorkflowError(
            f"config: scene {wildcards.scene!r}: scenes.{wildcards.scene}.segment.backend: "
            f"'provided' needs scenes.{wildcards.scene}.capture.masks (an id PNG or a folder "
            "of PNGs); or choose the opencv backend"
        )
    return os.path.join(capture["path"], capture["masks"])


def segment_table(wildcards):
    table = segment_settings(wildcards).get("table")
    if table is None:
        return None
    return os.path.join(capture_dir(wildcards), table)


def segment_input(wildcards):
    """A synthetic capture is one directory output; a user's files each, so that editing one
    re-runs the checkpoint."""
    if is_synthetic(wildcards.scene):
        return [capture_dir(wildcards)]
    files = [
        segment_image(wildcards),
        segment_masks(wildcards),
        segment_table(wildcards),
    ]
    return [path for path in files if path is not None]


def segment_options(wildcards):
    """Flags: the backend, its inputs and its settings."""
    settings = segment_settings(wildcards)
    options = [f"--backend {segment_backend(wildcards)}"]
    options.append(f"--min-instances {settings.get('min_instances', 3)}")
    for flag, value in (
        ("--masks", segment_masks(wildcards)),
        ("--table", segment_table(wildcards)),
    ):
        if value is not None:
            options.append(f"{flag} {shlex.quote(value)}")
    if segment_backend(wildcards) == "opencv":
        if settings.get("exemplar") is not None:
            options.append("--exemplar " + " ".join(map(str, settings["exemplar"])))
        options.append(set_options(settings.get("opencv", {})))
    return " ".join(option for option in options if option)


def segmented_instances(wildcards):
    """The instance ids the segment checkpoint found (1 .. N): the input function of the
    per-instance rules downstream, which therefore wait for the checkpoint."""
    folder = checkpoints.segment.get(scene=wildcards.scene).output[0]
    with open(os.path.join(folder, "instances.json")) as handle:
        return [entry["id"] for entry in json.load(handle)["instances"]]


checkpoint segment:
    """The copies of the object in the duplicates photograph: masks/<image stem>.png (uint16
    instance ids), instances.json (boxes, areas, scores) and overlay.png."""
    input:
        segment_input,
    output:
        report(
            directory("results/{scene}/segmentation"),
            patterns=["{name}.png"],
            caption="../report/segment.rst",
            category="Segmentation",
            labels={"scene": "{scene}", "figure": "{name}"},
        ),
    log:
        "results/{scene}/logs/segment.log",
    benchmark:
        "results/{scene}/benchmarks/segment.tsv"
    conda:
        "../../envs/render.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        image=segment_image,
        options=segment_options,
    shell:
        "invrender --log {log} segment {params.image:q} --out {output} {params.options}"
