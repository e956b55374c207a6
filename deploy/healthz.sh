#!/bin/bash
# sray-healthz [PORT]: exit 0 when the coordinator's HTTP endpoint on
# 127.0.0.1:PORT (default 9100, its --http-listen) answers GET /healthz
# with 200; print why and exit 1 otherwise.
#
# The container healthcheck of deploy/compose.yaml. The image has bash but
# no curl or wget; this needs nothing else (bash's /dev/tcp), so the
# runtime image stays Debian slim plus one binary. tests/it/deploy.rs runs it
# against a listener answering 200, one answering 503 and a closed port.
set -u
port="${1:-9100}"
if ! exec 3<>"/dev/tcp/127.0.0.1/$port"; then
    echo "sray-healthz: nothing listens on 127.0.0.1:$port" >&2
    exit 1
fi
printf 'GET /healthz HTTP/1.1\r\nHost: 127.0.0.1:%s\r\nConnection: close\r\n\r\n' "$port" >&3
status=""
IFS= read -r -t 5 status <&3
exec 3<&-
case "$status" in
    "HTTP/1."?" 200"*) exit 0 ;;
esac
echo "sray-healthz: /healthz answered: ${status:-nothing within 5 s}" >&2
exit 1
