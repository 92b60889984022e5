export PYTHONPATH=/work/wt-lead/src
PY=/work/main/.venv/bin/python
