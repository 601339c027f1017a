"""One module per physical process: orchestration only, the arithmetic lives in `kernels/`.

Each module declares the phase it runs in and, beside each other, `prognostic_state()` (every
array a bitwise restart needs) and `restore()`.
"""
