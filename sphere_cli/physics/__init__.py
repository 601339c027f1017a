"""One module per physical process: orchestration only, the arithmetic lives in `kernels/`.

A module of the step derives from `module.Module` and defines the hooks it takes part in, with
`prognostic_state()` (every array a bitwise restart needs) and `restore()` side by side.
"""
