<?xml version="1.0" encoding="UTF-8"?>
<!-- Hand written after CiA 311: the configuration of one I/O node (node 12, 250 kbit/s) with actual values and
     the names a system integrator gave (denotation). -->
<ISO15745ProfileContainer xmlns="http://www.canopen.org/xml/1.0" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance">
  <ISO15745Profile>
    <ProfileHeader><ProfileIdentification>CANopen device profile</ProfileIdentification><ProfileRevision>1</ProfileRevision><ProfileName>IO-8</ProfileName><ProfileSource/><ProfileClassID>Device</ProfileClassID><ISO15745Reference><ISO15745Part>1</ISO15745Part><ISO15745Edition>1</ISO15745Edition><ProfileTechnology>CANopen</ProfileTechnology></ISO15745Reference></ProfileHeader>
    <ProfileBody xsi:type="ProfileBody_Device_CANopen" fileName="io_node12.xdc" fileCreator="Hand" fileCreationDate="2024-03-02" fileVersion="1">
      <DeviceIdentity>
        <vendorName>Example IO</vendorName>
        <vendorID>0x00000ABC</vendorID>
        <productName>IO-8 digital module</productName>
        <productID>0x00000008</productID>
      </DeviceIdentity>
    </ProfileBody>
  </ISO15745Profile>
  <ISO15745Profile>
    <ProfileHeader><ProfileIdentification>CANopen communication network profile</ProfileIdentification><ProfileRevision>1</ProfileRevision><ProfileName>IO-8</ProfileName><ProfileSource/><ProfileClassID>CommunicationNetwork</ProfileClassID><ISO15745Reference><ISO15745Part>1</ISO15745Part><ISO15745Edition>1</ISO15745Edition><ProfileTechnology>CANopen</ProfileTechnology></ISO15745Reference></ProfileHeader>
    <ProfileBody xsi:type="ProfileBody_CommunicationNetwork_CANopen" fileName="io_node12.xdc" fileCreator="Hand" fileCreationDate="2024-03-02" fileVersion="1">
      <ApplicationLayers>
        <CANopenObjectList>
          <CANopenObject index="1000" name="Device type" objectType="7" dataType="0007" accessType="ro" defaultValue="0x00030191" PDOmapping="no"/>
          <CANopenObject index="1001" name="Error register" objectType="7" dataType="0005" accessType="ro" defaultValue="0" PDOmapping="no"/>
          <CANopenObject index="1017" name="Producer heartbeat time" objectType="7" dataType="0006" accessType="rw" defaultValue="0" actualValue="500" PDOmapping="no"/>
          <CANopenObject index="1018" name="Identity object" objectType="9" subNumber="2">
            <CANopenSubObject subIndex="00" name="Highest sub-index supported" objectType="7" dataType="0005" accessType="ro" defaultValue="1" PDOmapping="no"/>
            <CANopenSubObject subIndex="01" name="Vendor-ID" objectType="7" dataType="0007" accessType="ro" defaultValue="0x00000ABC" PDOmapping="no"/>
          </CANopenObject>
          <CANopenObject index="1800" name="TPDO1 communication parameter" objectType="9">
            <CANopenSubObject subIndex="00" name="Highest sub-index supported" objectType="7" dataType="0005" accessType="ro" defaultValue="1" PDOmapping="no"/>
            <CANopenSubObject subIndex="01" name="COB-ID used by TPDO" objectType="7" dataType="0007" accessType="rw" defaultValue="$NODEID+0x180" actualValue="0x18C" PDOmapping="no"/>
          </CANopenObject>
          <CANopenObject index="6200" name="Write outputs 8-bit" objectType="8" subNumber="3">
            <CANopenSubObject subIndex="00" name="Number of output groups" objectType="7" dataType="0005" accessType="ro" defaultValue="2" PDOmapping="no"/>
            <CANopenSubObject subIndex="01" name="Outputs 1-8" objectType="7" dataType="0005" accessType="rww" defaultValue="0" actualValue="0x0F" denotation="Conveyor lamps" PDOmapping="RPDO"/>
            <CANopenSubObject subIndex="02" name="Outputs 9-16" objectType="7" dataType="0005" accessType="rww" defaultValue="0" denotation="Spare" PDOmapping="RPDO"/>
          </CANopenObject>
        </CANopenObjectList>
      </ApplicationLayers>
      <TransportLayers><PhysicalLayer><baudRate defaultValue="250 Kbps"><supportedBaudRate value="250 Kbps"/><supportedBaudRate value="1 Mbps"/></baudRate></PhysicalLayer></TransportLayers>
      <NetworkManagement>
        <CANopenGeneralFeatures granularity="8" nrOfRxPDO="1" nrOfTxPDO="1"/>
        <CANopenMasterFeatures/>
        <deviceCommissioning nodeID="12" nodeName="Conveyor IO" actualBaudRate="250 Kbps" networkNumber="1" networkName="Line 2" CANopenManager="false"/>
      </NetworkManagement>
    </ProfileBody>
  </ISO15745Profile>
</ISO15745ProfileContainer>
