#!/bin/sh
# Links a HAL realtime module as LinuxCNC's Makefile.modinc does for uspace: only the symbols
# listed in the object's .rtapi_export section (rtapi_app_main, rtapi_app_exit, the module
# parameters) are global in the shared object.
#   link_module.sh CC OBJECT OUTPUT.so [LDFLAG...]
set -e
cc=$1 obj=$2 so=$3
shift 3
tmp=${so%.so}
ld -d -r -o "$tmp.tmp" "$obj"
objcopy -j .rtapi_export -O binary "$tmp.tmp" "$tmp.sym"
{ echo '{ global : '; tr -s '\0' < "$tmp.sym" | xargs -r0 printf '%s;\n' | grep .; echo 'local : * ; };'; } > "$tmp.ver"
"$cc" -shared -Bsymbolic "$@" -Wl,--version-script,"$tmp.ver" -o "$so" "$obj" -lm -lpthread
chmod -x "$so"
