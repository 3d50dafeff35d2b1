"""placeholder"""
HELP = "compare (not yet)"
def add_arguments(p):
    p.add_argument("run_dir", nargs="*")
def run(args):
    return 2
