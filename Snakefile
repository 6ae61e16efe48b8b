"""invrender: captures of real spaces in, editable and relightable scenes out.

One rule per stage (workflow/rules/<stage>.smk), each calling one `invrender <stage>` command;
artifacts land in results/{scene}/ (docs/architecture.md, "The stage contract"). The default
config is the embedded demo: `snakemake --cores 2` builds three small synthetic scenes (room,
boxes, living), one per mode, end to end.
"""


configfile: "config/config.yaml"


report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"
include: "workflow/rules/synthesize.smk"
include: "workflow/rules/cameras.smk"
include: "workflow/rules/geometry.smk"
include: "workflow/rules/gradients.smk"
include: "workflow/rules/milo.smk"
include: "workflow/rules/segment.smk"
include: "workflow/rules/duplicates.smk"
include: "workflow/rules/duplicates_material.smk"
include: "workflow/rules/bake.smk"
include: "workflow/rules/features.smk"
include: "workflow/rules/render.smk"
include: "workflow/rules/export.smk"
include: "workflow/rules/evaluate.smk"
include: "workflow/rules/edit.smk"
include: "workflow/rules/accuracy.smk"
include: "workflow/rules/room_box.smk"
include: "workflow/rules/room_lights.smk"
include: "workflow/rules/room_objects.smk"
include: "workflow/rules/room_materials.smk"


# Trivial steps run where snakemake runs (on a cluster: the login node), not through the queue:
# the target, and the bakes (maps written onto the mesh: seconds and ~130 MB in the demo's
# benchmark records, where a queue's wait would be most of their time).
localrules:
    all,
    bake,
    bake_duplicates,


rule all:
    default_target: True
    input:
        [target for scene in SCENES for target in scene_targets(scene)],
