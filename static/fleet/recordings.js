// The recordings page: a recording under way, look again once it may have ended (the page opens no socket).
const underWay = "#recordings tr[data-status=queued], #recordings tr[data-status=recording]";
if (document.querySelector(underWay)) setTimeout(() => location.reload(), 5000);
