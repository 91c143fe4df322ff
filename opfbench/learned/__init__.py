"""Local rules fitted to the certified optimum: the families with their fits and the parameters
files (`rules`), and the fitted rules a run carries (`fitted`); the training runs are the
study's (`opfbench.study.training`)."""
