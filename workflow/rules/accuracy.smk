rule recovery_run:
    """One configuration of the scene's recovery sweep (config accuracy.recovery): its stage
    trained with the run's settings, the maps baked and scored against the truth, each by the
    stage's own command (`invrender accuracy-run`: run.json, train/, scene/, score/)."""
    input:
        unpack(recovery_run_inputs),
    output:
        directory("results/{scene}/accuracy_runs/{run}"),
    log:
        "results/{scene}/logs/recovery_run/{run}.log",
    benchmark:
        "results/{scene}/benchmarks/recovery_run/{run}.tsv"
    wildcard_constraints:
        scene=scenes_pattern(SYNTHETIC),
        run="[A-Za-z0-9.-]+",
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=8000,
        runtime=accuracy_runtime,
        gpu=gpu_request,
    params:
        options=recovery_run_options,
        spp=recovery_score_spp,
        seed=config["evaluate"]["seed"],
        device=device_option,
    shell:
        "invrender --log {log} accuracy-run --out {output} {params.options} --spp {params.spp}"
        " --seed {params.seed} {params.device}"


rule accuracy:
    """What accuracy costs in time on this scene: every knob of the forward renderer, the
    gradients and the training run, each against a converged reference of the same scene;
    the Pareto front, the knee (a config snippet) and the floors, with their causes."""
    input:
        unpack(accuracy_inputs),
        scene="results/{scene}/scene",
        features="results/{scene}/features.json",
    output:
        report(
            directory("results/{scene}/accuracy"),
            patterns=["{name}.png", "{name}.html"],
            caption="../report/accuracy.rst",
            category="Accuracy",
            subcategory="{scene}",
            labels={"scene": "{scene}", "figure": "{name}"},
        ),
    log:
        "results/{scene}/logs/accuracy.log",
    benchmark:
        "results/{scene}/benchmarks/accuracy.tsv"
    conda:
        "../../envs/render.yaml"
    threads: 2
    resources:
        mem_mb=4000,
        runtime=accuracy_runtime,
        gpu=gpu_request,
    params:
        options=accuracy_options,
        budget=config["accuracy"]["budget"],
        default_spp=config["render"]["spp"],
        gradient_spp=config["gradients"]["spp"],
        seed=config["accuracy"]["seed"],
        device=device_option,
    shell:
        "invrender --log {log} accuracy --scene {input.scene} --features {input.features}"
        " --out {output} --budget {params.budget} --default-spp {params.default_spp}"
        " --gradient-spp {params.gradient_spp} --seed {params.seed} {params.options}"
        " {params.device}"


rule summary:
    """The scene's numbers for people: the metrics beside the papers' and each rule's time and
    memory from its benchmark record, as tables and a figure."""
    input:
        summary_inputs,
    output:
        report(
            directory("results/{scene}/summary"),
            patterns=["{name}.png", "{name}.html"],
            caption="../report/summary.rst",
            category="Summary",
            subcategory="{scene}",
            labels={"scene": "{scene}", "table": "{name}"},
        ),
    log:
        "results/{scene}/logs/summary.log",
    conda:
        "../../envs/render.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    shell:
        "invrender --log {log} summary --results results/{wildcards.scene} --out {output}"
