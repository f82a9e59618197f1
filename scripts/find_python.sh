# Sourced by the scripts: find_python X.Y prints an interpreter of Python X.Y, or nothing.
# Looks at $PYTHON_FOR_BPY, pythonX.Y, python3 and python on the PATH, then pyenv's versions (whose
# shims run only the selected version).
find_python() {
  local candidate
  for candidate in "${PYTHON_FOR_BPY:-}" "python$1" python3 python \
      "$(command -v pyenv >/dev/null && pyenv root)/versions/$1"*/bin/python"$1"; do
    if [ -n "$candidate" ] && "$candidate" -c \
        "import sys; sys.exit(sys.version_info[:2] != tuple(map(int, '$1'.split('.'))))" >/dev/null 2>&1; then
      echo "$candidate"
      return
    fi
  done
}
