# Sourced by the scripts: an install into a venv that runs once per version of the file holding its
# pins (a run otherwise repeats ~15 s of pip). The digest of that file is kept in the venv.
#   install_is_current VENV FILE   true when VENV's last successful install was for this FILE
#   mark_installed VENV FILE       record it, after the install succeeded
_pins_digest() {
  "$1/bin/python" -c "import hashlib, sys; print(hashlib.sha256(open(sys.argv[1], 'rb').read()).hexdigest())" "$2"
}
install_is_current() {
  [ "$(cat "$1/.kd_preview_installed" 2>/dev/null)" = "$(_pins_digest "$1" "$2")" ]
}
mark_installed() {
  _pins_digest "$1" "$2" > "$1/.kd_preview_installed"
}
