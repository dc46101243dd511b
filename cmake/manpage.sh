#!/bin/sh
# One manual page from a program's own --help and --version, with Debian's
# help2man (docs/install.md). Run at build time (cmake/ManipPackaging.cmake):
#   manpage.sh HELP2MAN APP_DIR APP VERSION OUT.1.gz
# * NAME's one-line description: the first --help line after "<app> <version>: ",
#   cut before the first " (", ";" or a final ".".
# * OPTIONS: help2man on the --help text up to the end of CLI11's option list.
#   The footer after it (exit-code rows, what each code means, method lists)
#   is kept line for line (roff no-fill) in EXIT STATUS (blocks whose heading
#   names codes) and NOTES (the others) instead of being reflowed into one
#   paragraph.
# * A program without --version gets VERSION.
# help2man runs a stand-in named like the program that prints the captured
# texts, so the usage line names no build directory. SOURCE_DATE_EPOCH, when
# set, dates the page (help2man honours it). gzip -9n: maximum compression,
# no name or time stamp in the header (Debian policy 12.1; reproducible).
set -eu
help2man=$1 app_dir=$2 app=$3 version=$4 out=$5
export LC_ALL=C.UTF-8 COLUMNS=100
work="$out.d"
rm -rf "$work"
mkdir -p "$work/bin"
trap 'rm -rf "$work" "$out.tmp" "${out%.gz}.tmp"' EXIT
# Run by its bare name: "Usage: <app> ..." whatever the build directory.
PATH="$app_dir:$PATH" "$app" --help > "$work/help.full" || { echo "manpage.sh: $app --help failed" >&2; exit 1; }
if ! PATH="$app_dir:$PATH" "$app" --version > "$work/version.txt" 2> /dev/null || ! grep -q "^$app " "$work/version.txt"; then
  echo "$app $version" > "$work/version.txt"
fi
name=$(head -1 "$work/help.full" | sed -e "s/^$app\( [0-9][^:]*\)\{0,1\}: *//" -e 's/ (.*//' -e 's/;.*//' -e 's/\.$//')
[ -n "$name" ] && [ "$name" != "$(head -1 "$work/help.full")" ] || name="part of manip $version"

awk -v head="$work/help.txt" -v inc="$work/include.h2m" '
  function roff(s) {
    gsub(/\\/, "\\e", s); gsub(/-/, "\\-", s)
    if (s ~ /^[.\047]/) s = "\\&" s
    return s
  }
  state == "" && /^Options:/ { state = "options" }
  state == "options" && /^[^ ]/ && !/^(Options|Positionals|Subcommands):/ { state = "footer" }
  state != "footer" { print > head; next }
  # Exit-code blocks: short rows, kept as printed (no-fill). Other blocks:
  # one filled paragraph per entry ("  name: text"; deeper indent continues it).
  /^[^ ]/ { kind = ($0 ~ /[Cc]odes/) ? "exit" : "notes"
            txt[kind] = txt[kind] ".PP\n" (kind == "exit" ? ".nf\n" : "") roff($0) "\n"; next }
  /^$/ { if (kind == "exit") txt[kind] = txt[kind] ".fi\n"; next }
  kind == "notes" && /^  [^ ]/ { sub(/^ +/, ""); txt[kind] = txt[kind] ".IP \"\" 2\n" roff($0) "\n"; next }
  kind == "notes" { sub(/^ +/, ""); txt[kind] = txt[kind] roff($0) "\n"; next }
  { txt[kind] = txt[kind] roff($0) "\n" }
  END {
    if (txt["exit"] != "") printf "[EXIT STATUS]\n%s.fi\n", txt["exit"] > inc
    if (txt["notes"] != "") printf "[NOTES]\n%s", txt["notes"] > inc
    printf "[SEE ALSO]\nThe manip documentation: docs/ of the sources, /usr/share/doc/manip/ in the Debian\npackage (cli.md: the flags every program shares; exit\\-codes.md: the one exit\\-code table).\n" > inc
  }' "$work/help.full"

cat > "$work/bin/$app" <<STANDIN
#!/bin/sh
case "\$1" in
  --help) cat '$work/help.txt' ;;
  --version) cat '$work/version.txt' ;;
  *) exit 2 ;;
esac
STANDIN
chmod 755 "$work/bin/$app"
page=${out%.gz}
PATH="$work/bin:$PATH" "$help2man" --locale=C.UTF-8 --no-info --section=1 --name="$name" --source="manip $version" --manual=manip \
  --include="$work/include.h2m" --output="$page.tmp" "$app"
gzip -9nc "$page.tmp" > "$out.tmp"
rm -f "$page.tmp"
mv "$out.tmp" "$out"
