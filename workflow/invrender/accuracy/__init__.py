"""The `accuracy` stage: what accuracy costs in time, measured on the scene itself.

Each knob is swept against a converged reference of the same scene, error and time in one run:
forward rendering (``forward.py``: spp, bounces, each effect `features` switches, NEE against
MILO's mixture, resolution), gradients (``gradients.py``: spp and bounces against a high-spp
reference gradient) and recovery (``recovery.py``: the training logs' metrics against wall time).
``front.py`` finds the Pareto front, the knee and the bias floors; ``figures.py`` draws them;
``stage.py`` writes accuracy_vs_time.csv, accuracy.json, the report's tables and the plots.
``summary.py`` writes the report's other tables (rule summary): each rule's time and memory from
its benchmark record, and the metrics beside the papers'. ``budgets.py`` holds the two sizes,
`quick` (CI) and `full` (the README's figures).
"""
