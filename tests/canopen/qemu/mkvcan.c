/* Create and bring up a vcan interface through rtnetlink (busybox `ip`
 * cannot create type vcan). Usage: mkvcan vcan0. Static, for the qemu guest
 * of run_vcan_test.sh. */
#include <linux/if.h>
#include <linux/if_link.h>
#include <linux/netlink.h>
#include <linux/rtnetlink.h>
#include <stdio.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

static void add_attr(struct nlmsghdr* n, int type, const void* data, int len) {
  struct rtattr* rta = (struct rtattr*)((char*)n + NLMSG_ALIGN(n->nlmsg_len));
  rta->rta_type = type;
  rta->rta_len = RTA_LENGTH(len);
  if (len) memcpy(RTA_DATA(rta), data, len);
  n->nlmsg_len = NLMSG_ALIGN(n->nlmsg_len) + RTA_ALIGN(rta->rta_len);
}

int main(int argc, char** argv) {
  const char* name = argc > 1 ? argv[1] : "vcan0";
  char buf[512];
  memset(buf, 0, sizeof buf);
  struct nlmsghdr* n = (struct nlmsghdr*)buf;
  n->nlmsg_len = NLMSG_LENGTH(sizeof(struct ifinfomsg));
  n->nlmsg_type = RTM_NEWLINK;
  n->nlmsg_flags = NLM_F_REQUEST | NLM_F_CREATE | NLM_F_EXCL | NLM_F_ACK;
  add_attr(n, IFLA_IFNAME, name, (int)strlen(name) + 1);
  struct rtattr* linkinfo = (struct rtattr*)((char*)n + NLMSG_ALIGN(n->nlmsg_len));
  add_attr(n, IFLA_LINKINFO, NULL, 0);
  add_attr(n, IFLA_INFO_KIND, "vcan", 4);
  linkinfo->rta_len = (unsigned short)((char*)n + n->nlmsg_len - (char*)linkinfo);
  int fd = socket(AF_NETLINK, SOCK_RAW, NETLINK_ROUTE);
  if (fd < 0) { perror("netlink"); return 1; }
  struct sockaddr_nl sa = {.nl_family = AF_NETLINK};
  if (sendto(fd, n, n->nlmsg_len, 0, (struct sockaddr*)&sa, sizeof sa) < 0) { perror("sendto"); return 1; }
  char ack[512];
  int r = (int)recv(fd, ack, sizeof ack, 0);
  struct nlmsghdr* a = (struct nlmsghdr*)ack;
  if (r > 0 && a->nlmsg_type == NLMSG_ERROR) {
    struct nlmsgerr* e = (struct nlmsgerr*)NLMSG_DATA(a);
    if (e->error) { fprintf(stderr, "RTM_NEWLINK %s: %s\n", name, strerror(-e->error)); return 1; }
  }
  close(fd);
  int s = socket(AF_INET, SOCK_DGRAM, 0);
  struct ifreq ifr;
  memset(&ifr, 0, sizeof ifr);
  strncpy(ifr.ifr_name, name, IFNAMSIZ - 1);
  if (ioctl(s, SIOCGIFFLAGS, &ifr) < 0) { perror("SIOCGIFFLAGS"); return 1; }
  ifr.ifr_flags |= IFF_UP;
  if (ioctl(s, SIOCSIFFLAGS, &ifr) < 0) { perror("SIOCSIFFLAGS"); return 1; }
  printf("%s up\n", name);
  return 0;
}
