"""The repository's files matching glob patterns, for the checks in scripts/ (lint, ROS-free core).

In a git checkout: what `git ls-files` lists (tracked and untracked, without the ignored ones).
Outside one (an exported tarball, a copy without .git): a walk of the tree that leaves out what
.gitignore leaves out here (build folders, output, caches) and hidden folders. Either way the
caller must treat an empty list as a failure: a check over zero files proves nothing.
"""
import fnmatch
import os
import subprocess

# Folders the walk skips: .gitignore's build and output folders, caches, installed npm modules.
SKIPPED = {"output", "node_modules", "__pycache__"}


def git_files(root, patterns):
    """Files git lists under root, or None when root is not in a git work tree (or git is missing)."""
    try:
        result = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard", *patterns],
                                cwd=root, capture_output=True, text=True, check=False)
    except FileNotFoundError:
        return None
    if result.returncode != 0:
        return None
    return [line for line in result.stdout.splitlines() if line and os.path.exists(os.path.join(root, line))]


def walked_files(root, patterns):
    """Files under root whose relative path matches a pattern (as git's pathspec globs: '*' crosses '/')."""
    found = []
    for parent, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if not d.startswith(".") and d not in SKIPPED)
        for name in sorted(files):
            path = os.path.relpath(os.path.join(parent, name), root)
            if any(fnmatch.fnmatchcase(path, pattern) for pattern in patterns):
                found.append(path)
    return found


def repo_files(root, *patterns):
    files = git_files(root, patterns)
    return sorted(files) if files is not None else walked_files(root, patterns)
