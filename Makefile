# graspnet_torch: `make help` lists the targets.
VENV   ?= .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
STAMP  := $(VENV)/.installed

.DEFAULT_GOAL := help
.PHONY: help install demo docs robots test test-fast lint sync-defaults reproduce reproduce-quick experiment bench bench-fcnn bench-fcnn-train bench-solver bench-validation bench-arm bench-manus bench-any-hand bench-meshes bench-calls bench-api bench-quality bench-synthesis bench-cold-start bench-decomposition bench-contact bench-retarget bench-proposal bench-solvers bench-reports report-arm report-contact report-synthesis report-hands report-manus report-reach fcnn posture urdf clean

help:  ## list the targets
	@grep -hE '^[a-zA-Z_-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  make %-10s %s\n", $$1, $$2}'

$(STAMP): pyproject.toml
	test -x $(PY) || python3 -m venv $(VENV)
	$(PIP) install --upgrade pip >/dev/null
	$(PIP) install torch==2.13.0
	$(PIP) install -e '.[dev]'
	touch $(STAMP)

install: $(STAMP)  ## create .venv if missing (torch first, pinned) and install the package

demo: $(STAMP)  ## solve the default problem (glass3, 20 trials, R3: no finger through the glass) -> outputs/demo/
	$(PY) scripts/solve_grasp.py task=glass3 reward=r3 hydra.run.dir=outputs/demo
	@echo "next: look at outputs/demo/posture.png and learning.png; turn the grasp in 3D with"
	@echo "      $(PY) scripts/view.py outputs/demo   (then open the address it prints); curves: tensorboard --logdir outputs/demo/tb"

robots: $(STAMP)  ## table of the shipped robots and a picture of each -> outputs/robots/
	$(PY) scripts/inspect_robots.py hydra.run.dir=outputs/robots

test: $(STAMP)  ## ruff check + the layers (lint-imports) + the whole test suite on two processes (pytest -n 2; CI runs this)
	$(PY) -m ruff check .
	$(VENV)/bin/lint-imports
	$(PY) -m pytest -n 2 --dist loadscope

test-fast: $(STAMP)  ## the inner loop: every test not marked slow (pytest -m "not slow", < 1 min)
	$(PY) -m pytest -m "not slow"

reproduce: $(STAMP)  ## every experiment -> reports/REPRODUCTION.md and its figures (32 min on 2 cores before arm, random_hand, tradeoff, proxy)
	$(PY) scripts/reproduce.py out=reports hydra.run.dir=outputs/reproduce/full

reproduce-quick: $(STAMP)  ## the reduced protocol of every experiment (~2 min) -> outputs/reproduce-quick/REPRODUCTION.md
	$(PY) scripts/reproduce.py quick=true out=outputs/reproduce-quick hydra.run.dir=outputs/reproduce-quick

EXPERIMENT_RUN = $(PY) scripts/reproduce.py check=true out=outputs/experiment/$(1) hydra.run.dir=outputs/experiment/$(1) +experiment=$(1)

experiment: $(STAMP)  ## one experiment with its targets checked, E=<name> (configs/experiment/) -> outputs/experiment/<name>/
	@test -n "$(E)" || { echo "usage: make experiment E=<name> (configs/experiment/)"; exit 2; }
	$(call EXPERIMENT_RUN,$(E))

docs: $(STAMP)  ## the documentation site from docs/ (mkdocs --strict: a broken link or reference fails) -> outputs/site/
	NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict

lint: $(STAMP)  ## ruff check + the package's layers and no import cycles (lint-imports: [tool.importlinter])
	$(PY) -m ruff check .
	$(VENV)/bin/lint-imports

sync-defaults: $(STAMP)  ## write the defaults the YAML files under configs/ list from the settings dataclasses (their one source)
	$(PY) scripts/sync_defaults.py

bench: $(STAMP)  ## kinematics throughput against pytorch-kinematics
	$(PY) benchmarks/report.py bench_kinematics

bench-fcnn: $(STAMP)  ## FCNN finger IK against pytorch-kinematics PseudoInverseIK (accuracy, speed)
	$(PY) benchmarks/report.py bench_fcnn

bench-fcnn-train: $(STAMP)  ## time to train all five fingers of the hand from scratch
	$(PY) benchmarks/report.py bench_fcnn_training

bench-solver: $(STAMP)  ## iterations per second of the closed loop, 1 to 1000 trials
	$(PY) benchmarks/report.py bench_solver

bench-validation: $(STAMP)  ## start-up time the input checks add to a solve (target < 0.2 s)
	$(PY) benchmarks/report.py bench_validation

bench-arm: $(STAMP)  ## the arm loop with collision checking vs without (targets 1,000 it/s, 30,000 at T=1000)
	$(PY) benchmarks/report.py bench_arm

bench-manus: $(STAMP)  ## the MANUS loop with its defaults vs the bare loop (targets 2,000 it/s, 100,000 at T=1000)
	$(PY) benchmarks/report.py bench_manus

bench-any-hand: $(STAMP)  ## any hand by config (Dexmate F5D6, mimic joints): train, solve 40 problems, verify from the URDF (~7 min)
	$(PY) -c 'import dexmate_urdf' 2>/dev/null || $(PIP) install -e '.[hands]'
	$(PY) benchmarks/report.py any_hand

bench-meshes: $(STAMP)  ## mesh objects: the loop's speed vs the primitive (>= 0.5x); the experiment proxy: verdicts vs FCL (>= 99 %)
	$(PY) benchmarks/report.py mesh_objects
	$(call EXPERIMENT_RUN,proxy)

bench-calls: $(STAMP)  ## many calls: per-call overhead and single-problem wall time, gt.Solver beside gt.solve (targets 2 ms, 15 ms)
	$(PY) benchmarks/report.py calls

bench-api: $(STAMP)  ## the Python API from a plain program: solve_many problems/s, gt.Solver overhead; 1 thread vs torch's own (targets 1,000/s, 2 ms; ~1 min)
	$(PY) benchmarks/report.py api_speed

bench-quality: $(STAMP)  ## grasp quality per contact set (epsilon, sigma_min) beside an LP force-closure test, --check
	$(PY) benchmarks/report.py quality

bench-contact: $(STAMP)  ## the surface contact model's wall time beside the point model's (target <= 2x)
	$(PY) benchmarks/report.py contact_models

bench-retarget: $(STAMP)  ## sequences: tracking beside dex-retargeting on the same frames (installs the retarget extra; ~2 min)
	$(PY) -c 'import dex_retargeting' 2>/dev/null || $(PIP) install -e '.[retarget]'
	$(PY) benchmarks/report.py retarget

bench-synthesis: $(STAMP)  ## grasps from an object: verified grasps/s and time to the first beside the baseline, 10 objects (targets 5/s, 2 s; ~2 min)
	$(PY) benchmarks/report.py synthesis

bench-cold-start: $(STAMP)  ## a never-seen object, empty cache, fresh process: time to the first verified grasp, 50 objects (targets 1.5 s median, 4 s p95; ~20 min) -> reports/cold_start.md
	$(PY) benchmarks/cold_start.py --report reports/cold_start.md --check

bench-decomposition: $(STAMP)  ## convex pieces of never-seen meshes: the package's decomposition beside CoACD's full search and planes alone, seconds and fit (~10 min)
	$(PY) benchmarks/report.py decomposition

bench-proposal: $(STAMP)  ## gt.solve_many from posture proposals beside random starts, 1000 hand problems (targets 5x, 3000/s; ~1 min)
	$(PY) benchmarks/report.py proposal

bench-solvers: $(STAMP)  ## the experiment solvers: every solver (srv, paper, cmaes, dls) on the same problems, targets (~11 min)
	$(call EXPERIMENT_RUN,solvers)

bench-reports: $(STAMP)  ## every benchmark the docs quote, each in a fresh process -> reports/bench_*.md, a missed target said there, not stopping the rest (~1 h; each bench-* target writes its own)
	$(PY) -c 'import dexmate_urdf' 2>/dev/null || $(PIP) install -e '.[hands]'
	$(PY) -c 'import dex_retargeting' 2>/dev/null || $(PIP) install -e '.[retarget]'
	-$(PY) benchmarks/report.py bench_kinematics bench_fcnn bench_fcnn_training bench_solver bench_threads bench_validation \
	  bench_arm bench_manus any_hand mesh_objects calls api_speed quality contact_models retarget synthesis decomposition proposal
	test -d examples/schunk_svh/dex-urdf || $(PY) scripts/fetch_hands.py
	-$(PY) benchmarks/report.py any_hand --args "--robot examples/schunk_svh/schunk_svh_right.yaml --fingers 2 5" --as any_hand_schunk
	-$(PY) benchmarks/report.py sweep_launchers --args=--long

report-manus: $(STAMP)  ## the experiment manus: section 7.2, 64 positions x 30 runs, DLS and CMA-ES, checks, Fig. 12 (~7 min)
	$(call EXPERIMENT_RUN,manus)

report-reach: $(STAMP)  ## the experiment reach: motions from home to every arm and MANUS grasp, re-checked, checks (~5 min)
	$(call EXPERIMENT_RUN,reach)

report-contact: $(STAMP)  ## the experiment contact as in reports/contact.md (50 poses per task, 30 arm seeds, cone 60 left out): pads vs points, MuJoCo (~10 min)
	$(PY) scripts/reproduce.py check=true out=outputs/experiment/contact hydra.run.dir=outputs/experiment/contact +experiment=contact experiments.contact.arm_seeds=30 'experiments.contact.variants=[point,surface,surface_cmaes,surface_dls]'

report-synthesis: $(STAMP)  ## the experiment synthesis as in reports/synthesis.md (100 objects; hand, TriFinger, arm + hand; the baseline): MuJoCo, checks (~20 min)
	$(PY) scripts/reproduce.py check=true out=outputs/experiment/synthesis hydra.run.dir=outputs/experiment/synthesis +experiment=synthesis

report-hands: $(STAMP)  ## the experiment hands (-> reports/hands.md): synthesis on every example hand over 40 everyday objects at real scale, MuJoCo, checks (~1 h; pip install -e '.[hands]' and scripts/fetch_hands.py first for dexmate, schunk, ability, inspire, icub)
	rm -f outputs/experiment/hands/REPRODUCTION.md; $(PY) scripts/reproduce.py check=true out=outputs/experiment/hands hydra.run.dir=outputs/experiment/hands +experiment=hands; \
	status=$$?; test -f outputs/experiment/hands/REPRODUCTION.md && cp outputs/experiment/hands/REPRODUCTION.md reports/hands.md \
	&& cp outputs/experiment/hands/hands_*.png reports/; exit $$status

report-arm: $(STAMP)  ## the experiments table3, fig10, arm: Tables 3-4, ANOVA, Figs. 6/8/9/10, CMA-ES, the product (~6 min)
	$(call EXPERIMENT_RUN,table3)
	$(call EXPERIMENT_RUN,fig10)
	$(call EXPERIMENT_RUN,arm)

fcnn: $(STAMP)  ## retrain the shipped FCNN checkpoint checkpoints/hand/fcnn.pt (fixed seed)
	$(PY) scripts/train_fcnn.py robot=hand export=true hydra.run.dir=outputs/train_fcnn/hand-export

posture: posture-hand posture-arm_hand posture-manus posture-trifinger  ## retrain every shipped posture proposal model (fixed seed; ~2-3 min each)

posture-%: $(STAMP)  ## retrain one posture proposal model: posture-hand, posture-arm_hand, posture-manus, posture-trifinger
	$(PY) scripts/train_posture.py robot=$(if $(filter trifinger,$*),examples/trifinger/trifinger.yaml,$*) progress=false hydra.run.dir=outputs/train_posture/$*-export

urdf: $(STAMP)  ## regenerate the URDFs from urdf/build.py
	$(PY) urdf/build.py

clean:  ## remove outputs and caches (keeps .venv)
	rm -rf outputs multirun .pytest_cache .ruff_cache .import_linter_cache
