"""The segment checkpoint (issue 13, duplicates scenes): the copies of the object in the
photograph, as results/{scene}/segmentation/ (masks/<image stem>.png, instances.json,
overlay.png). A checkpoint: how many instances there are, and so the per-instance jobs
downstream, is known only once it has run (segmented_instances below).

Its settings, per scene, for workflow/schemas/config.schema.yaml (under
scenes.additionalProperties.properties, beside `capture`):

  segment:
    description: >-
      The `segment` checkpoint (`invrender segment`, duplicates scenes): the copies of the
      object in the photograph, as an instance-id PNG, instances.json and an overlay
      (`docs/segment.md`).
    type: object
    additionalProperties: false
    default: {}
    properties:
      backend:
        description: >-
          `opencv`: found in the photograph, no downloaded weights; `provided`: the masks
          `capture.masks` names (a synthetic scene: its true masks, for testing what follows).
        enum: [opencv, provided]
        default: opencv
      table:
        description: >-
          `provided`, with an id image: JSON or CSV listing the ids it may hold (relative to
          the capture directory); an id beyond it stops the stage.
        type: string
        minLength: 1
      exemplar:
        description: >-
          `opencv`: a box around one copy, [x0, y0, x1, y1] in pixels: its colours guide the
          search (without one: the colours the image's border lacks).
        type: array
        items: {type: number, minimum: 0}
        minItems: 4
        maxItems: 4
      min_instances:
        description: Fewer instances found stops the stage (the duplicates mode needs 3).
        type: integer
        minimum: 3
        default: 3
      opencv:
        description: >-
          `opencv` backend settings (invrender/segment/opencv.py, OpenCVSettings):
          core_threshold, likelihood_ratio, border_fraction, close_fraction, join_fraction,
          split_factor, min_area_fraction, grabcut_iterations, extent_fraction, convex
          (docs/segment.md).
        type: object
        default: {}
        additionalProperties: false
        properties:
          core_threshold:
            description: >-
              First guess: a colour with P(c | border) / P(c) below this is the object's.
            type: number
            exclusiveMinimum: 0
            exclusiveMaximum: 1
            default: 0.3
          likelihood_ratio:
            description: >-
              A colour is the object's where P(c | object) is above this times P(c | support).
            type: number
            exclusiveMinimum: 0
            default: 2.0
          border_fraction:
            description: >-
              Width of the border band that shows the support, of the shorter side.
            type: number
            exclusiveMinimum: 0
            exclusiveMaximum: 0.5
            default: 0.04
          close_fraction:
            description: >-
              Closing radius over gaps in a copy's colours, of sqrt(expected area).
            type: number
            minimum: 0
            default: 0.15
          join_fraction:
            description: >-
              Pieces of one copy this far apart (of sqrt(expected area)) may join.
            type: number
            minimum: 0
            default: 0.5
          split_factor:
            description: >-
              A core of this many expected areas or more is touching copies, split.
            type: number
            exclusiveMinimum: 1
            default: 1.5
          min_area_fraction:
            description: >-
              Pieces below this share of the expected area are specks, dropped.
            type: number
            minimum: 0
            default: 0.3
          grabcut_iterations:
            description: >-
              GrabCut iterations for the parts in support-like colours; 0: none.
            type: integer
            minimum: 0
            default: 5
          extent_fraction:
            description: >-
              GrabCut may add pixels this far from a core, of sqrt(expected area).
            type: number
            minimum: 0
            default: 0.4
          convex:
            description: >-
              Each core's convex hull added to its instance (false: a non-convex object).
            type: boolean
            default: true
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
    capture = SCENES[wildcards.scene]["capture"]
    if "image" in capture:
        return os.path.join(capture["path"], capture["image"])
    return str(photographs(Path(capture["path"], "images"))[0])


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
            patterns=["overlay.png"],
            caption="../report/segment.rst",
            category="Segmentation",
            labels={"scene": "{scene}", "file": "overlay.png"},
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
