"""Files of a source tree for the code checks (class_sizes.py, function_lengths.py)."""
import os


def source_files(paths, suffixes):
    """Every file under the given directories whose name ends with one of `suffixes`, plus the
    files given directly (whatever their suffix)."""
    files = []
    for p in paths:
        if os.path.isdir(p):
            for d, _, fs in os.walk(p):
                files += [os.path.join(d, f) for f in fs if f.endswith(tuple(suffixes))]
        else:
            files.append(p)
    return files
