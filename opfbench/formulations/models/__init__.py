"""The models of the OPF problem (`formulations.problem`), one module each: every module
here declares itself with `@formulation` (`formulations.model`, which says what a model
is and finds them all), so a new model is one new file and nothing else. `conic` is what
the conic models share; `opfbench strategies` lists the models' strategies and roles.

A model writes its variables and branch flows into the problem's rows; the solvers
(`formulations.solvers`) and the runner above them (`formulations.runner`) are shared.
"""
